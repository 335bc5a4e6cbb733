"""`training.shared_prefix`: sequences' common opening run once gives the loss and the gradients of running
each sequence whole."""

from __future__ import annotations

import pytest

from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS
IGNORE = -100


def _sequences(opening: int, seed: int = 0) -> list:
    """Four (ids, labels) sequences: a shared opening of `opening` ids, then each its own ids, labelled on a
    stretch in the middle and at the end (as a packed episode's actions)."""
    import random

    rng = random.Random(seed)
    head = [rng.randrange(5, 200) for _ in range(opening)]
    out = []
    for n in (9, 30, 17, 4):
        ids = head + [rng.randrange(5, 200) for _ in range(n)]
        labels = [IGNORE] * len(ids)
        for i in (*range(len(ids) - 3, len(ids)), opening + n // 2):
            labels[i] = ids[i]
        out.append((ids, labels))
    return out


def _plain(model, sequences):
    import torch

    losses = [model(input_ids=torch.tensor([ids]), labels=torch.tensor([labels])).loss for ids, labels in sequences]
    return torch.stack(losses).mean()


def _loss_and_grads(model, loss_fn, sequences):
    import torch

    model.zero_grad()
    loss = loss_fn(model, sequences)
    loss.backward()
    return float(loss.detach()), torch.cat([p.grad.flatten() for p in model.parameters() if p.grad is not None])


@pytest.mark.parametrize("opening", [0, 1, 40])
def test_loss_and_gradients_are_those_of_whole_sequences(tiny, opening):
    import torch
    from transformers import AutoModelForCausalLM

    from adaptbench.training.shared_prefix import common_prefix, shared_prefix_loss

    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32)
    seqs = _sequences(opening)
    assert common_prefix(seqs) == opening
    plain_loss, plain_grads = _loss_and_grads(model, _plain, seqs)
    shared_loss, shared_grads = _loss_and_grads(model, lambda m, s: shared_prefix_loss(m, s, min_shared=1), seqs)
    assert shared_loss == pytest.approx(plain_loss, rel=1e-5)
    assert torch.allclose(shared_grads, plain_grads, atol=1e-5, rtol=1e-4)


def test_the_prefix_stops_before_the_first_target():
    from adaptbench.training.shared_prefix import common_prefix

    ids = list(range(10, 30))
    early = [IGNORE] * 5 + ids[5:]  # first target at 5: its logits come from position 4
    late = [IGNORE] * 15 + ids[15:]
    assert common_prefix([(ids, late), (ids + [7], [IGNORE] * 15 + ids[15:] + [7])]) == 14
    assert common_prefix([(ids, early), (ids, late)]) == 4
    assert common_prefix([(ids, late), ([99] + ids[1:], late)]) == 0  # nothing shared
    assert common_prefix([(ids, late), (ids, late)]) == 14  # identical sequences keep a token of their own


def test_a_sequence_without_a_target_is_refused(tiny):
    import torch
    from transformers import AutoModelForCausalLM

    from adaptbench.training.shared_prefix import shared_prefix_loss

    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32)
    with pytest.raises(ValueError, match="no labelled token"):
        shared_prefix_loss(model, [([5, 6, 7], [IGNORE] * 3)])


def test_prompt_action_logprobs_are_those_of_whole_sequences(tiny):
    """Two prompts that share an opening, three actions: each entry (and its gradient) is the summed
    log-probability of the action scored after its prompt whole."""
    import random

    import torch
    from transformers import AutoModelForCausalLM

    from adaptbench.training.shared_prefix import prompt_action_logprobs

    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32)
    rng = random.Random(1)
    head = [rng.randrange(5, 200) for _ in range(30)]
    prompts = [head + [rng.randrange(5, 200) for _ in range(n)] for n in (6, 11)]
    actions = [[rng.randrange(5, 200) for _ in range(n)] for n in (1, 4, 7)]
    got = prompt_action_logprobs(model, prompts, actions)
    for i, p in enumerate(prompts):
        for j, a in enumerate(actions):
            logp = model(input_ids=torch.tensor([p + a])).logits[0, len(p) - 1:-1].log_softmax(-1)
            want = logp[torch.arange(len(a)), torch.tensor(a)].sum()
            assert float(got[i, j].detach()) == pytest.approx(float(want.detach()), abs=1e-4)
    model.zero_grad()
    (got[0, 1] - got[1, 2]).backward()
    shared = torch.cat([q.grad.flatten() for q in model.parameters() if q.grad is not None])
    model.zero_grad()
    whole = []
    for p, a in ((prompts[0], actions[1]), (prompts[1], actions[2])):
        logp = model(input_ids=torch.tensor([p + a])).logits[0, len(p) - 1:-1].log_softmax(-1)
        whole.append(logp[torch.arange(len(a)), torch.tensor(a)].sum())
    (whole[0] - whole[1]).backward()
    plain = torch.cat([q.grad.flatten() for q in model.parameters() if q.grad is not None])
    assert torch.allclose(shared, plain, atol=1e-5, rtol=1e-4)
    with pytest.raises(ValueError):
        prompt_action_logprobs(model, prompts, [[]])
