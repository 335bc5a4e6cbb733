"""One update's loss over several sequences that open with the same tokens, their shared opening run once.

Every planner sequence the student trains on (a packed episode, an answer row) starts with the same
~1,230-token system message: the instructions, the actions and the house's layout. Trained one sequence at
a time, each pays for that opening again. `shared_prefix_loss` runs the sequences' common prefix through
the model once, keeps its keys and values (with their gradients' history), and runs each sequence's
remainder after them; the loss and its gradients are those of running every sequence whole (checked in
tests/llm/test_shared_prefix.py). It saves less than the tokens suggest: 8 whole-prompt answer rows (half
their tokens shared) ran 1.1-1.2x faster than one by one on a quiet core, and four episodes no faster
(bench/bench_shared_prefix.py; the remainder's attention after a cache takes an explicit mask).

The loss is each sequence's mean over its labelled tokens, averaged over the sequences: every sequence
weighs the same, as in `adapt model student --accumulate`.
"""

from __future__ import annotations

IGNORE = -100  # label of a token the loss skips (as in training.pretrain)


def common_prefix(sequences) -> int:
    """How many leading tokens every `(ids, labels)` sequence shares and that can be run once: the common
    run of ids, ending before the token whose logits predict the first labelled token of any sequence (so
    no loss is taken inside the prefix), and leaving every sequence at least one token of its own."""
    first, *rest = [ids for ids, _ in sequences]
    n = min(len(ids) for ids in [first, *rest]) - 1
    for ids in rest:
        n = next((i for i in range(n) if ids[i] != first[i]), n)
    for _, labels in sequences:
        labelled = next((i for i, t in enumerate(labels) if t != IGNORE), len(labels))
        n = min(n, labelled - 1)
    return max(n, 0)


def _prefix_layers(model, torch, ids: list) -> tuple:
    """Per-layer (keys, values) of one pass over `ids`, their gradients' history kept."""
    return _extend(model, torch, ids, 0, (), logits_to_keep=1)[1]


def _suffix_loss(model, torch, ids, labels, start: int, prefix_layers):
    """The mean loss over the labelled tokens of `ids[start:]`, run after the prefix's keys and values."""
    logits = _extend(model, torch, ids, start, prefix_layers)[0]
    targets = torch.tensor(labels[start + 1:], device=logits.device)
    return torch.nn.functional.cross_entropy(logits[:-1].float(), targets, ignore_index=IGNORE)


def shared_prefix_loss(model, sequences, min_shared: int = 32):
    """The mean over `sequences` (`(ids, labels)` pairs) of each one's mean token loss, with their common
    prefix (`common_prefix`) run through `model` once when it is at least `min_shared` tokens; gradients
    flow through the prefix's keys and values. Each sequence runs on its own after it (no padding). A
    sequence without a labelled token is refused."""
    import torch

    for ids, labels in sequences:
        if len(ids) != len(labels) or all(t == IGNORE for t in labels[1:]):
            raise ValueError("a sequence has no labelled token after its first (or its labels do not match its ids)")
    start = common_prefix(sequences)
    start = start if start >= min_shared else 0
    layers = _prefix_layers(model, torch, sequences[0][0][:start]) if start else ()
    losses = [_suffix_loss(model, torch, ids, labels, start, layers) for ids, labels in sequences]
    return torch.stack(losses).mean()


def _extend(model, torch, ids: list, start: int, layers: tuple, logits_to_keep: int = 0):
    """Run `ids[start:]` after `layers` (the keys and values of `ids[:start]`; each call a fresh cache, so
    `layers` can serve several continuations): its logits (the last `logits_to_keep`, 0: all), and the keys
    and values of all of `ids` (gradients' history kept)."""
    from transformers import DynamicCache

    from ..llm.decode import cache_arg

    dev = model.device
    cache = DynamicCache(config=model.config)
    for layer, (keys, values) in enumerate(layers):
        cache.update(keys, values, layer)
    logits = model(input_ids=torch.tensor([ids[start:]], device=dev),
                   position_ids=torch.arange(start, len(ids), device=dev).unsqueeze(0),
                   use_cache=True, logits_to_keep=logits_to_keep, **cache_arg(model, cache)).logits
    return logits[0], tuple((layer.keys, layer.values) for layer in cache.layers)


def _shared_run(seqs: list) -> int:
    """How many leading ids all of `seqs` share."""
    n = min(len(s) for s in seqs)
    for s in seqs[1:]:
        n = next((i for i in range(n) if s[i] != seqs[0][i]), n)
    return n


def prompt_action_logprobs(model, prompts: list, actions: list):
    """A `len(prompts)` x `len(actions)` tensor: the summed log-probability of each action's token ids after
    each prompt's, with gradients. The prompts' common opening runs once, each prompt's remainder once, and
    each action after its prompt's keys and values: what scoring every prompt + action whole gives, at the
    cost of the prompts alone (the answer-contrast loss of bench/cook_and_read.py)."""
    import torch

    if not prompts or not actions or any(not p for p in prompts) or any(not a for a in actions):
        raise ValueError("every prompt and every action needs at least one token")
    heads = [p[:-1] for p in prompts]
    start = _shared_run(heads)
    shared = _extend(model, torch, heads[0][:start], 0, ())[1] if start else ()
    rows = []
    for prompt, head in zip(prompts, heads, strict=True):
        layers = _extend(model, torch, head, start, shared)[1] if len(head) > start else shared
        rows.append(torch.stack([_action_tokens(model, torch, head, prompt[-1], action, layers).sum()
                                 for action in actions]))
    return torch.stack(rows)


def _action_tokens(model, torch, head: list, last: int, action, layers: tuple):
    """The log-probability of each of `action`'s tokens after `head` (whose keys and values are `layers`) and
    the prompt's `last` token."""
    action = list(action)
    logits = _extend(model, torch, head + [last] + action, len(head), layers)[0]
    logp = logits[:-1].float().log_softmax(-1)
    return logp[torch.arange(len(action)), torch.tensor(action, device=logp.device)]


def completion_token_logprobs(model, prompt, completions: list) -> list:
    """Each completion's per-token log-probabilities after `prompt` (token ids), with gradients: the prompt
    runs once, each completion after its keys and values (DPO's sums with a per-token mask,
    bench/anchored_rdpo.py)."""
    import torch

    if not prompt or any(not c for c in completions):
        raise ValueError("the prompt and every completion need at least one token")
    head = list(prompt[:-1])
    layers = _extend(model, torch, head, 0, (), logits_to_keep=1)[1] if head else ()
    return [_action_tokens(model, torch, head, prompt[-1], c, layers) for c in completions]
