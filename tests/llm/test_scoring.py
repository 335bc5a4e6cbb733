"""Scoring what the model did (issue 19 items 1, 2, 7): a completion carries its generated ids and
`score` on them gives back the log-probabilities the model had while generating; a text is scored as a
complete answer, its end token included; batched scoring (the prompt read once) equals scoring one
continuation at a time; whether the generated ids were the tokenizer's own is recorded per step and
counted; scores in float32 whatever the model's precision."""

from __future__ import annotations

import pytest

from .conftest import SKIP_MODELS, play

pytestmark = [SKIP_MODELS, pytest.mark.paper]


def _sharp(tiny, **kw):
    """The tiny model with weights redrawn at std 0.5 (its output then depends on the context)."""
    from .test_decode import _sharp as sharp

    return sharp(tiny, **kw)


@pytest.fixture(scope="module")
def sharp(tiny):
    return _sharp(tiny)


def _prompt(domain, backend):
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder

    return render(backend.tokenizer, PromptBuilder(domain, "planner").prompt(play(domain)[0].view()))


def _grammar(domain):
    from adaptbench.grammars import GrammarCache
    from adaptbench.runtime.index import runtime_index

    ep, _ = play(domain)
    return GrammarCache(runtime_index(domain).grammar).state("eggs", ep.env.observed()).text


def _recorded_loop(monkeypatch):
    """Log-probabilities of each token the decode loop picks, from the model's logits before the grammar
    masks them: {request row: {token index: log-probability vector}}."""
    import torch

    from adaptbench.llm import decode

    seen: dict = {}
    real = decode.Picker.pick

    def pick(self, logits, active, steps):
        lp = torch.log_softmax(logits.float(), -1)
        for k, i in enumerate(active):
            seen.setdefault(i, {})[steps[i]] = lp[k].clone()
        return real(self, logits, active, steps)

    monkeypatch.setattr(decode.Picker, "pick", pick)
    return seen


def _recorded_generate(backend):
    """The same for `model.generate`: every step's last logits, row by row (no fast-forwarding)."""
    import torch

    steps: list = []
    model = backend.model
    real = model.forward

    def forward(*args, **kw):
        out = real(*args, **kw)
        steps.append(torch.log_softmax(out.logits[:, -1].float(), -1))
        return out

    model.forward = forward
    return steps


@pytest.mark.parametrize("loop", [True, False], ids=["decode-loop", "model.generate"])
def test_scoring_a_completions_ids_gives_its_generation_time_logprobs(domain, tiny, monkeypatch, loop):
    """`score(prompt, [completion.token_ids])` reproduces, within 1e-4 in float32, the log-probabilities
    the model gave each generated token while generating it (unmasked: scores are forced passes without
    the grammar), EOS included; rows of a batch with and without a grammar."""
    from adaptbench.llm.backend import Request

    b = _sharp(tiny, dtype="float32")
    b.loop = loop
    prompt, grammar = _prompt(domain, b), _grammar(domain)
    reqs = [Request(prompt, grammar, (), 24), Request(prompt, None, (), 12)]
    if loop:  # a shorter prompt too (model.generate would left-pad it: the sharpened model's logits then move
        reqs.append(Request(prompt[:-40], grammar, (), 24))  # by up to 6e-4, padding numerics, not the ids)
    seen = _recorded_loop(monkeypatch) if loop else None
    steps = None if loop else _recorded_generate(b)
    outs = b.generate(reqs)
    b.model.__dict__.pop("forward", None)  # back to the class's forward
    eos = b.tokenizer.eos_token_id
    assert outs[0].token_ids[-1] == eos and outs[0].accepted  # a constrained action ends with its end token
    assert len(outs[1].token_ids) == outs[1].tokens == 12
    checked = 0
    for i, (req, out) in enumerate(zip(reqs, outs, strict=True)):
        (scored,) = b.score(req.prompt, [out.token_ids])
        assert scored.token_ids == out.token_ids and len(scored.logprobs) == len(out.token_ids)
        for j, t in enumerate(out.token_ids):
            at_generation = seen[i].get(j) if loop else steps[j][i]
            if at_generation is None:  # a token the grammar forced: the loop took it without a pass of its own
                continue
            assert scored.logprobs[j] == pytest.approx(at_generation[t].item(), abs=1e-4), (i, j)
            checked += 1
    assert checked >= len(outs[1].token_ids) + 2


def test_a_text_is_scored_as_a_complete_answer_with_its_end_token(domain, sharp):
    """Without the end token a continuation that is a prefix of another is never charged for stopping
    there: "Look for eggs" is now the ids of the text and the end token the chat template closes an
    assistant turn with, and the end token's log-probability is the price of stopping."""
    import math

    from adaptbench.llm.chat import end_token

    b = sharp
    prompt = _prompt(domain, b)
    end = end_token(b.tokenizer)
    assert end == b.tokenizer.convert_tokens_to_ids("<|end|>")  # what the tiny template writes after a turn
    short, longer = "Look for eggs", "Look for eggs_0"
    ids = b.encode(short)
    text, plain, whole = b.score(prompt, [short, ids, ids + [end]])
    assert text.token_ids == (*ids, end) and text.logprobs == pytest.approx(whole.logprobs, abs=1e-6)
    assert text.logprobs[:-1] == pytest.approx(plain.logprobs, abs=1e-6)
    stop = text.logprobs[-1]
    assert stop < 0 and sum(text.logprobs) == pytest.approx(sum(plain.logprobs) + stop)
    (long_,) = b.score(prompt, [longer])  # the same tokens, then more: the short answer stops where this goes on
    assert long_.token_ids[:len(ids)] == tuple(ids) and long_.token_ids[len(ids)] != end
    # scored alone against in a batch of three: float32 sums in another order differ by ~1e-6 at |x| ~ 10
    assert long_.logprobs[:len(ids)] == pytest.approx(text.logprobs[:-1], abs=1e-5)
    assert text.mean_prob == pytest.approx(sum(math.exp(x) for x in text.logprobs) / (len(ids) + 1))


@pytest.mark.parametrize("sharpened", [False, True], ids=["tiny", "sharpened"])
def test_batched_scoring_equals_one_at_a_time_and_a_plain_forward_pass(domain, backend, sharp, sharpened):
    """The prompt read once and its continuations read together after its cache (right-padded, lengths
    1 to 20, text and ids) give what one call per continuation gives, within 1e-5 (2e-5 on the sharpened
    model, whose logits reach -20: float32 rounding of different matrix shapes), and what a plain forward
    pass over prompt + continuation gives."""
    import torch

    b = sharp if sharpened else backend
    tol = 2e-5 if sharpened else 1e-5
    prompt = _prompt(domain, b)
    conts = ["Look for eggs", "Declare Done", 'Ask "Would you like milk in your scrambled eggs today?"', "x",
             [b.tokenizer.eos_token_id], b.encode("Open fridge_0")]
    batched = b.score(prompt, conts)
    alone = [b.score(prompt, [c])[0] for c in conts]
    p = b.encode(prompt)
    for got, one in zip(batched, alone, strict=True):
        assert got.token_ids == one.token_ids
        assert got.logprobs == pytest.approx(one.logprobs, abs=tol)
        with torch.no_grad():
            logits = b.model(input_ids=torch.tensor([p + list(got.token_ids)])).logits[0].float()
        logp = torch.log_softmax(logits, -1)
        want = [logp[len(p) - 1 + j, t].item() for j, t in enumerate(got.token_ids)]
        assert got.logprobs == pytest.approx(want, abs=1e-4)
    small = type(b).__new__(type(b))
    small.__dict__.update(b.__dict__, batch_size=2)  # several passes after one reading of the prompt
    for got, want in zip(small.score(prompt, conts), batched, strict=True):
        assert got.logprobs == pytest.approx(want.logprobs, abs=tol)


def test_scores_in_float32_from_a_bfloat16_model(domain, tiny):
    """`score(..., dtype="float32")` on a bfloat16 backend runs the checkpoint in float32: equal to the
    float32 backend's scores within 1e-5, where the bfloat16 model's own differ; `score_dtype` says which."""
    from adaptbench.llm.hf import TransformersBackend

    f32, bf16 = TransformersBackend(str(tiny), dtype="float32"), TransformersBackend(str(tiny), dtype="bfloat16")
    prompt = _prompt(domain, f32)
    conts = ["Look for eggs", "Declare Done"]
    want = f32.score(prompt, conts)
    for got, w in zip(bf16.score(prompt, conts, dtype="float32"), want, strict=True):
        assert got.logprobs == pytest.approx(w.logprobs, abs=1e-5)
    own = bf16.score(prompt, conts)
    assert max(abs(a - b) for s, w in zip(own, want, strict=True) for a, b in zip(s.logprobs, w.logprobs,
                                                                                  strict=True)) > 1e-4
    assert bf16.score_dtype("float32") == "float32" and bf16.score_dtype() == "bfloat16"
    assert str(bf16.model.dtype) == "torch.bfloat16"  # the generating model is left as it is
    with pytest.raises(ValueError, match="scoring dtype"):
        bf16.score(prompt, conts, dtype="float64")


def test_canonical_says_whether_ids_are_the_tokenizers_own(sharp):
    from adaptbench.llm.backend import canonical

    tok = sharp.tokenizer
    ids = sharp.encode("Move egg_0 to pan_0")
    assert canonical(tok, ids) and canonical(tok, ids + [tok.eos_token_id])
    split = [t for piece in ("Mo", "ve egg_0 to pan_0") for t in sharp.encode(piece)]
    assert tok.decode(split) == "Move egg_0 to pan_0" and split != ids
    assert not canonical(tok, split)


def test_the_canonical_flag_is_recorded_per_step_and_counted_by_eval(domain, tiny, tmp_path, capsys):
    """Sampled at temperature 1 under the grammar, the random tiny model's actions take other splits of
    the same bytes; every model step records its ids and whether they were canonical, and `adapt eval`
    counts the canonical ones per agent."""
    import json

    from adaptbench.cli.main import main
    from adaptbench.harness.batches import rollout_policy
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.backend import canonical
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.policies import LLMPolicy

    from .test_policies import _offline

    backend = TransformersBackend(str(tiny), temperature=1.0, seed=3)
    policy = LLMPolicy(backend, domain, "planner", max_tokens=24)
    out = tmp_path / "r.jsonl"
    jobs = [Job("planner", p, "eggs", 0) for p in ("juan", "miranda", "sarah")]
    assert rollout_policy(jobs, out, domain, policy, _offline, batch=3, progress=False, steps=6).errors == 0
    steps = [s for line in out.read_text().splitlines() for s in json.loads(line)["steps"]]
    assert len(steps) == 18
    flags = [s["stats"]["canonical"] for s in steps]
    assert flags == [canonical(backend.tokenizer, s["stats"]["token_ids"]) for s in steps]
    assert False in flags  # sampling under the grammar does split text other than the tokenizer
    assert main(["eval", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"canonical token ids: planner {sum(flags)}/{len(flags)} model steps" in text
