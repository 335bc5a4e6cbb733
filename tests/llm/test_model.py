"""The tiny model, grammar-constrained decoding and scoring on the CPU (skipped, saying why, without the
`models` extra)."""

from __future__ import annotations

import random

import pytest

from adaptbench.grammars import GrammarCache
from adaptbench.llm.chat import render
from adaptbench.llm.prompts import PromptBuilder
from adaptbench.runtime.index import runtime_index

from .conftest import SKIP_MODELS, play

pytestmark = SKIP_MODELS


def test_tiny_model_loads_through_the_auto_classes(tiny):
    from transformers import AutoModelForCausalLM, AutoTokenizer

    tok = AutoTokenizer.from_pretrained(tiny)
    model = AutoModelForCausalLM.from_pretrained(tiny)
    assert model.config.model_type == "llama" and model.config.vocab_size == len(tok)
    text = tok.apply_chat_template([{"role": "system", "content": "s"}, {"role": "user", "content": "u"}],
                                   tokenize=False, add_generation_prompt=True)
    assert text == "<|bos|><|system|>\ns<|end|>\n<|user|>\nu<|end|>\n<|assistant|>\n"
    with pytest.raises(Exception, match="unknown role robot"):
        tok.apply_chat_template([{"role": "robot", "content": "x"}], tokenize=False)
    assert len(tok.tokenize("Move egg_10 to pan_0")) <= 8  # trained on the domain: ids are few tokens


def _grammars(domain, n: int, rng):
    """(variant, level, grammar text, view text) for n rows over tasks, states, variants and levels."""
    ix = runtime_index(domain)
    cache = GrammarCache(ix.grammar)
    out = []
    for i in range(n):
        task = rng.choice(list(domain.task))
        ep, _ = play(domain, task=task, seed=i % 3, steps=("Look for eggs", "Open fridge_0")[: i % 3])
        variant = ("default", "never_ask", "ask_only")[i % 3]
        level = ("observed", "typed")[i % 2]
        out.append((variant, cache.state(task, ep.env.observed(), level, variant).text))
    return out


def _sampler(tiny):
    from adaptbench.llm.hf import TransformersBackend

    return TransformersBackend(str(tiny), batch_size=32, temperature=1.0, seed=1)


def test_every_constrained_completion_parses(domain, tiny):
    """A batch with a different grammar per row (variants, levels, states), sampled at temperature 1:
    every completion parses with the simulator's parser and obeys its own row's variant."""
    from adaptbench.llm.backend import Request

    rng = random.Random(0)
    backend = _sampler(tiny)
    parser = runtime_index(domain).parser
    rows = _grammars(domain, 12, rng)
    prompt = render(backend.tokenizer, PromptBuilder(domain, "planner").prompt(play(domain, steps=())[0].view()))
    reqs = [Request(prompt, g, (), 40) for _, g in rows] * 4
    outs = backend.generate(reqs)
    assert len(outs) == 48
    for (variant, _), out in zip(rows * 4, outs, strict=True):
        parsed = parser.parse(out.text)
        assert parsed is not None, out.text
        assert out.accepted
        assert (parsed.action == "ask") == (variant == "ask_only") or variant == "default", (variant, out.text)
    assert len({o.text for o in outs}) > 12  # sampling explores the grammar


@pytest.mark.slow
def test_500_random_model_generations_parse(domain, tiny):
    """The issue's bar: >= 500 generations of the random tiny model under the grammar, 0 unparsed."""
    from adaptbench.llm.backend import Request

    backend = _sampler(tiny)
    parser = runtime_index(domain).parser
    rows = _grammars(domain, 24, random.Random(1))
    prompt = "<|bos|><|user|>\nact<|end|>\n<|assistant|>\nAction: "
    outs = backend.generate([Request(prompt, g, (), 40) for _, g in rows] * 21)
    assert len(outs) >= 500
    assert [o.text for o in outs if parser.parse(o.text) is None] == []


def test_unconstrained_rows_and_stops(backend):
    from adaptbench.llm.backend import Request

    outs = backend.generate([Request("<|bos|>hello", None, (), 5), Request("<|bos|>hello", None, ("e",), 30),
                             Request("<|bos|>hello", 'start: "Declare" " " "Done"', (), 30)])
    assert outs[0].tokens == 5 and outs[0].accepted is None
    assert "e" not in outs[1].text
    assert outs[2].text == "Declare Done" and outs[2].accepted
    assert 1 <= outs[2].stats["forced_tokens"] < outs[2].tokens  # a grammar of one sentence: the first token is picked, later ones forced


def test_bad_grammar_is_reported(backend):
    from adaptbench.llm.backend import Request

    with pytest.raises(ValueError, match="row 0"):
        backend.generate([Request("<|bos|>x", "start: NOPE", (), 4)])


def test_scores_match_an_unbatched_forward_pass(domain, backend):
    """Left-padded batched scoring equals scoring each sequence alone with a plain forward pass."""
    import torch

    prompt = render(backend.tokenizer, PromptBuilder(domain, "planner").prompt(play(domain)[0].view()))
    conts = ["Look for eggs", "Declare Done", 'Ask "Would you like milk in your scrambled eggs today?"', "x"]
    from adaptbench.llm.chat import end_token

    got = backend.score(prompt, conts)
    p = backend.encode(prompt)
    for s, c in zip(got, conts, strict=True):
        cont = backend.encode(c) + [end_token(backend.tokenizer)]  # a text is scored as a whole answer
        ids = p + cont
        with torch.no_grad():
            logits = backend.model(input_ids=torch.tensor([ids])).logits[0].float()
        logp = torch.log_softmax(logits, -1)
        want = [logp[len(p) - 1 + j, t].item() for j, t in enumerate(cont)]
        assert s.token_ids == tuple(cont)
        assert s.logprobs == pytest.approx(want, abs=2e-4)
        assert 0 < s.mean_prob < 1
    assert got[0].mean_prob == pytest.approx(sum(torch.tensor(got[0].logprobs).exp().tolist()) / 4)


def test_loading_a_model_freezes_the_heap_and_the_model_is_still_freed(tiny):
    """`hf.settle_heap`: what is alive after loading is kept out of the cyclic collector's scans, and a
    dropped backend and model are freed all the same (no reference cycles hold them)."""
    import gc
    import weakref

    from adaptbench.llm.hf import TransformersBackend

    backend = TransformersBackend(str(tiny))
    assert gc.get_freeze_count() > 0
    model, dropped = weakref.ref(backend.model), weakref.ref(backend)
    del backend
    assert model() is None and dropped() is None
