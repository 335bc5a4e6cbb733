"""The transformers backend's generation loop (`llm.decode`): batched rows with their own lengths and
grammars give what `model.generate` gives one prompt at a time, and an episode's later steps read only
their new tokens from the session's cache without changing what is generated."""

from __future__ import annotations

import pytest

from .conftest import SKIP_MODELS, play

pytestmark = [SKIP_MODELS, pytest.mark.paper]


def _sharp(tiny, **kw):
    """The tiny model with weights redrawn at std 0.5: its greedy output depends on the context (the
    freshly initialised model repeats one token whatever the prompt, which would prove nothing)."""
    import torch

    from adaptbench.llm.hf import TransformersBackend

    b = TransformersBackend(str(tiny), **kw)
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in b.model.parameters():
            if p.dim() == 2:
                p.copy_(torch.randn(p.shape, generator=g) * 0.5)
    return b


@pytest.fixture(scope="module")
def sharp(tiny):
    """A backend on the sharpened tiny model."""
    return _sharp(tiny)


def _prompts(domain, backend, n=4):
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder

    out = []
    for k in range(n):
        ep, made_after = play(domain, steps=("Look for eggs", "Open fridge_0", "Look for milk")[:k])
        out.append(render(backend.tokenizer, PromptBuilder(domain, "planner").prompt(ep.view(), made_after=made_after)))
    return out


def _grammar(domain, task="eggs"):
    from adaptbench.grammars import GrammarCache
    from adaptbench.runtime.index import runtime_index

    ep, _ = play(domain, steps=())
    return GrammarCache(runtime_index(domain).grammar).state(task, ep.env.observed()).text


def _one_by_one_with_generate(backend, reqs):
    out = []
    for r in reqs:
        prompt = backend.encode(r.prompt)
        from adaptbench.llm.constrained import GrammarProcessor, closing_tokens

        eos = backend.tokenizer.eos_token_id
        proc = (GrammarProcessor(backend.matchers, [r.grammar], eos, backend.vocab, [r.max_tokens],
                                 closing_tokens(backend.tokenizer, eos)) if r.grammar else None)
        out += backend._batch_hf([r], [prompt], proc, 0.0)
    return [o.text for o in out]


@pytest.mark.parametrize("constrained", [False, True])
def test_batched_rows_match_model_generate_one_at_a_time(domain, sharp, constrained):
    from adaptbench.llm.backend import Request

    g = _grammar(domain) if constrained else None
    reqs = [Request(p, g, (), 12 + 3 * i) for i, p in enumerate(_prompts(domain, sharp))]
    assert len({len(sharp.encode(r.prompt)) for r in reqs}) == len(reqs)  # rows of different lengths
    ours = sharp.generate(reqs)
    assert len({c.text for c in ours}) == len(reqs)  # the rows' outputs differ
    assert [c.text for c in ours] == _one_by_one_with_generate(sharp, reqs)
    if constrained:
        assert all(c.accepted for c in ours)
        assert sum(c.stats["forced_tokens"] for c in ours) > 0  # forced tokens taken without a forward pass


def test_a_session_reads_only_new_tokens_and_generates_the_same(domain, tiny):
    from adaptbench.llm.backend import Request

    cached, fresh = _sharp(tiny), _sharp(tiny, sessions=0)
    g = _grammar(domain)
    text = _prompts(domain, cached, 1)[0]
    forced = 0
    for step in range(4):
        a = cached.generate([Request(text, g, (), 16, session="ep")])[0]
        b = fresh.generate([Request(text, g, (), 16, session="ep")])[0]
        assert a.text == b.text
        forced += a.stats["forced_tokens"]
        assert b.stats["cached_tokens"] == 0
        if step:  # everything before this step's new turn came from the cache
            assert a.stats["cached_tokens"] > a.prompt_tokens - 40
        text = text + a.text + "<|end|>\n<|user|>\nObservation: nothing happens.<|end|>\n<|assistant|>\n"
    assert forced > 0  # a step read forced tokens together, and the next step reused that cache
    assert len(cached.sessions) == 1
    cached.release("ep")
    assert len(cached.sessions) == 0


def test_a_new_episode_starts_from_the_prefix_another_shares_and_generates_the_same(domain, tiny):
    """Episodes open with the same system message: a new session's first prompt reads only what follows
    the longest prefix it shares with a kept session; new sessions in one call read the prefix they
    share once and each start from it."""
    from adaptbench.llm.backend import Request
    from adaptbench.llm.decode import common_prefix

    cached, fresh = _sharp(tiny), _sharp(tiny, sessions=0)
    g = _grammar(domain)
    a, b, c = _prompts(domain, cached, 3)
    first = cached.generate([Request(a, g, (), 16, session="one")])[0]
    assert first.stats["cached_tokens"] == 0
    second = cached.generate([Request(c, g, (), 16, session="two")])[0]
    shared = sum(1 for _ in zip(cached.encode(a), cached.encode(c), strict=False))
    assert 64 <= second.stats["cached_tokens"] <= shared
    assert second.text == fresh.generate([Request(c, g, (), 16)])[0].text
    both = fresh.generate([Request(b, g, (), 16, session="x"), Request(c, g, (), 16, session="y")])
    common = common_prefix(cached.encode(b), cached.encode(c))  # read once, both rows start from it
    assert common >= 64 and [o.stats["cached_tokens"] for o in both] == [min(common, o.prompt_tokens - 1)
                                                                         for o in both]
    assert [o.text for o in both] == [fresh.generate([Request(p, g, (), 16)])[0].text for p in (b, c)]


def test_a_truncated_prompt_reuses_the_prefix_it_still_shares(domain, backend):
    from adaptbench.llm.backend import Request

    text = _prompts(domain, backend, 3)[2]
    backend.generate([Request(text, None, (), 4, session="cut")])
    shorter = text[: len(text) // 2] + "<|end|>\n<|assistant|>\n"
    out = backend.generate([Request(shorter, None, (), 4, session="cut")])[0]
    from adaptbench.llm.decode import common_prefix

    shared = common_prefix(backend.encode(text), backend.encode(shorter))
    assert shared > 64 and out.stats["cached_tokens"] == shared < out.prompt_tokens
    backend.release("cut")


def test_sessions_are_bounded_least_recently_used_first(domain, tiny):
    from adaptbench.llm.backend import Request
    from adaptbench.llm.hf import TransformersBackend

    b = TransformersBackend(str(tiny), sessions=2)
    text = _prompts(domain, b, 1)[0]
    for s in ("a", "b", "c"):
        b.generate([Request(text, None, (), 2, session=s)])
    assert len(b.sessions) == 2 and b.sessions.take("a") is None


def test_sampling_is_seeded(domain, tiny):
    from adaptbench.llm.backend import Request
    from adaptbench.llm.hf import TransformersBackend

    reqs = [Request(p, None, (), 16) for p in _prompts(domain, TransformersBackend(str(tiny)), 2)]
    runs = [[c.text for c in _sharp(tiny, temperature=1.0, seed=s).generate(reqs)] for s in (0, 0, 1)]
    assert runs[0] == runs[1] != runs[2]


def test_rows_of_several_sessions_read_their_new_tokens_together_and_generate_the_same(domain, tiny):
    from adaptbench.llm import decode
    from adaptbench.llm.backend import Request

    cached, fresh = _sharp(tiny), _sharp(tiny, sessions=0)
    cached.prefill_together = True  # the GPU's way, checked here on the CPU
    g = _grammar(domain)
    texts = _prompts(domain, cached, 3)
    calls = []
    many = decode.prefill_many

    def spy(*a, **kw):
        calls.append(len(a[1]))
        return many(*a, **kw)

    decode.prefill_many = spy
    try:
        for step in range(3):
            reqs = [Request(t, g if i != 1 else None, (), 10 + 2 * i, session=f"s{i}") for i, t in enumerate(texts)]
            a, b = cached.generate(reqs), fresh.generate(reqs)
            assert [c.text for c in a] == [c.text for c in b]
            turn = f"<|end|>\n<|user|>\nObservation: step {step}{'.' * step}<|end|>\n<|assistant|>\n"
            texts = [t + c.text + turn * (1 + i) for i, (t, c) in enumerate(zip(texts, a, strict=True))]
    finally:
        decode.prefill_many = many
    # step 1: the shared system message read once, then the two rows whose rest is short in one pass;
    # steps 2 and 3: the three rows' new tokens in one forward pass
    assert calls == [2, 3, 3]


def test_piecewise_encoding_equals_whole_encoding(domain, backend):
    from adaptbench.llm.chat import encode

    tok = backend.tokenizer
    for text in _prompts(domain, backend, 4):
        assert encode(tok, text) == tok(text, add_special_tokens=False)["input_ids"]
    assert tok.__dict__["_adapt_encoder"]["pieces"] is not None  # the tiny tokenizer's pieces add up


def test_a_tokenizer_whose_pieces_do_not_add_up_is_encoded_whole():
    from adaptbench.llm.chat import encode

    class PrefixingTokenizer:  # adds a "prefix space" token to every call, like some SentencePiece set-ups
        added_tokens_encoder = {"<s>": 0}

        def __call__(self, text, add_special_tokens=False):
            return {"input_ids": [9] + [ord(c) for c in text.replace("<s>", "\0")]}

    tok = PrefixingTokenizer()
    text = "hello<s>world"
    assert encode(tok, text) == tok(text)["input_ids"]
    assert tok.__dict__["_adapt_encoder"]["pieces"] is None


def test_grouped_heads_left_to_sdpa_give_the_same_logits_and_the_switch_is_restored(tiny, monkeypatch):
    """A masked pass over several new tokens (padding inside, a cache before) with torch's SDPA handling
    the grouped key/value heads equals transformers' own way (repeating them)."""
    import os

    import torch
    from transformers import DynamicCache

    from adaptbench.llm.decode import GQA_FLAG, cache_arg, grouped_heads

    monkeypatch.delenv(GQA_FLAG, raising=False)
    model = _sharp(tiny).model
    assert model.config.num_key_value_heads < model.config.num_attention_heads  # the tiny model groups heads
    g = torch.Generator().manual_seed(0)
    ids = torch.randint(0, 3000, (3, 40), generator=g)
    mask = torch.ones(3, 40, dtype=torch.long)
    mask[1, :8], mask[2, 30:33] = 0, 0
    pos = (mask.cumsum(-1) - 1).clamp(min=0)

    def logits():
        with torch.no_grad():
            cache = DynamicCache(config=model.config)
            model(input_ids=ids[:, :30], attention_mask=mask[:, :30], position_ids=pos[:, :30],
                  **cache_arg(model, cache))
            return model(input_ids=ids[:, 30:], attention_mask=mask, position_ids=pos[:, 30:],
                         cache_position=torch.arange(30, 40), **cache_arg(model, cache)).logits

    plain = logits()
    with grouped_heads(model):
        assert os.environ[GQA_FLAG] == "1"
        grouped = logits()
    assert GQA_FLAG not in os.environ
    assert torch.allclose(plain, grouped, atol=1e-5)


@pytest.mark.parametrize("loop", [True, False], ids=["decode-loop", "model.generate"])
def test_a_rollout_raises_no_deprecation_warning_from_transformers(domain, tiny, tmp_path, loop):
    """Issue 17 item 8: a short rollout on both generation paths with FutureWarning and DeprecationWarning
    turned into errors (transformers 5.2x warns on every forward pass given `past_key_values=`; its
    `deprecate_kwarg` names the caller, torch's Module, as the warning's place, so no module filter)."""
    import json
    import warnings

    from adaptbench.agents.users import OfflineUser
    from adaptbench.harness.batches import rollout_policy
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.policies import LLMPolicy

    backend = TransformersBackend(str(tiny))
    backend.loop = loop
    policy = LLMPolicy(backend, domain, "planner", max_tokens=12)
    jobs = [Job("planner", p, "eggs", 0) for p in ("juan", "miranda")]
    out = tmp_path / "w.jsonl"
    with warnings.catch_warnings():
        warnings.simplefilter("error", FutureWarning)
        warnings.simplefilter("error", DeprecationWarning)
        res = rollout_policy(jobs, out, domain, policy, OfflineUser, batch=2, progress=False, steps=3)
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert res.errors == 0, [r.get("error") for r in recs]
    assert len(recs) == 2 and all(len(r["steps"]) == 3 for r in recs)


def _actions(domain, backend, batch: int, steps: int = 4) -> dict:
    from adaptbench.harness.batches import run_batched
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.policies import LLMPolicy
    from adaptbench.runtime.users import OfflineUser

    jobs = [Job("planner", p, t, 0) for p in ("juan", "miranda") for t in ("eggs", "cereal")] + \
        [Job("planner", "juan", "eggs", 1)]
    policy = LLMPolicy(backend, domain, "planner", max_tokens=14)
    recs = run_batched(jobs, domain, policy, OfflineUser, batch=batch, steps=steps)
    return {(r["persona"], r["task"], r["seed"]): [s["action"] for s in r["steps"]] for r in recs}


@pytest.mark.parametrize("batch,ride", [(1, False), (5, True), (5, False), (2, True)])
def test_the_cache_path_acts_as_model_generate_does_greedy_under_the_grammar(domain, tiny, batch, ride, monkeypatch):
    """Speed must not change behaviour: constrained planner rollouts through the loop's cache path (a
    single row in its session's own buffer; several in one batch buffer with stopped rows riding and
    compaction; new episodes from a shared prefix) take the same actions as `model.generate` reading
    every step's prompt whole, one episode at a time. `ride`: stopped rows stay in the batch until half
    have stopped (a large model's way; the tiny model's small caches are compacted at once)."""
    from adaptbench.llm import decode

    if ride:
        monkeypatch.setattr(decode, "COMPACT_BYTES", 0)
    ours, plain = _sharp(tiny), _sharp(tiny, sessions=0, batch_size=1)
    plain.loop = False
    got, want = _actions(domain, ours, batch), _actions(domain, plain, 1)
    assert got == want
    assert len({tuple(a) for a in want.values()}) > 1  # the episodes act differently


@pytest.mark.parametrize("lean", [True, False])
def test_a_single_row_decodes_in_its_sessions_buffer_with_no_attention_mask(domain, tiny, lean):
    """One row: every decoding pass goes without an explicit attention mask (no padding: the kernels
    that take none serve) and the session keeps the same cache layers step after step (written in
    place, not copied per step or grown by concatenation per token); through the lean pass
    (`one_row.step`, the CPU default for a Llama model) or the model's forward."""
    from adaptbench.llm import one_row
    from adaptbench.llm.backend import Request

    b = _sharp(tiny)
    b.model.__dict__["_adapt_lean"] = lean
    masks, steps = [], []

    def hook(module, args, kwargs):
        if kwargs["input_ids"].shape[1] == 1:
            masks.append(kwargs.get("attention_mask"))

    real = one_row.step

    def counted(*args):
        steps.append(args[2:])
        return real(*args)

    handle = b.model.register_forward_pre_hook(hook, with_kwargs=True)
    one_row.step = counted
    try:
        g = _grammar(domain)
        text = _prompts(domain, b, 1)[0]
        kept = []
        for step in range(3):
            a = b.generate([Request(text, g, (), 16, session="ep")])[0]
            kept.append(b.sessions._items["ep"][1])
            text = text + a.text + f"<|end|>\n<|user|>\nObservation: step {step}.<|end|>\n<|assistant|>\n"
    finally:
        handle.remove()
        one_row.step = real
    passes = steps if lean else masks
    assert passes and all(m is None for m in masks)
    assert not (steps if not lean else masks)  # one path or the other, never both
    assert all(x is y for x, y in zip(kept[0], kept[2], strict=True))  # the same layer objects, reused


def test_passes_under_a_narrow_grammar_compute_only_the_allowed_logits_and_pick_the_same(domain, tiny, monkeypatch):
    """On the CPU a pass whose rows' grammars allow few tokens computes only those tokens' logits (the
    output layer is a fifth of SmolLM2's weights): the same completions as with the whole layer, batched
    and one row, constrained and (all logits) unconstrained."""
    from adaptbench.llm import decode
    from adaptbench.llm.backend import Request

    b = _sharp(tiny)
    g = _grammar(domain)
    prompts = _prompts(domain, b, 3)
    reqs = [Request(p, g if i != 2 else None, (), 14) for i, p in enumerate(prompts)]
    narrow, real = [], decode._logits

    def spy(model, head, **kw):
        narrow.append(head is not None)
        return real(model, head, **kw)

    monkeypatch.setattr(decode, "_logits", spy)
    assert not decode.narrow_head(b.model)  # the tiny model's output layer is too small to gain
    monkeypatch.setattr(decode, "HEAD_MIN", 0)
    assert decode.narrow_head(b.model)
    runs = [[c.text for c in b.generate(reqs)], [c.text for c in b.generate(reqs[:2])],
            [c.text for c in b.generate(reqs[:1])]]
    assert any(narrow) and not all(narrow)
    monkeypatch.setattr(decode, "narrow_head", lambda model: False)
    narrow.clear()
    assert runs == [[c.text for c in b.generate(reqs)], [c.text for c in b.generate(reqs[:2])],
                    [c.text for c in b.generate(reqs[:1])]]
    assert not any(narrow)
