"""Prompts end on a token boundary of a real tokenizer (llm/boundary.py): with a GPT-2 style byte-level
tokenizer, whose words carry their leading space (` Look`), the model reads `...Action:` and the
constrained first token is the unconstrained distribution restricted to the grammar; the tiny tokenizer
(space kept with the word before) is left as it was."""

from __future__ import annotations

import pytest

from tests.llm.conftest import MISSING, play

pytestmark = pytest.mark.skipif(bool(MISSING), reason=f"models extra not installed (missing {MISSING})")

ACTIONS = ("Look for eggs", "Open fridge_0", 'Ask "How do you like your eggs?"', "Declare Done")


@pytest.fixture(scope="module")
def spaced(domain, tmp_path_factory):
    """A GPT-2 style tokenizer (byte-level BPE, the GPT-2 split: ` Look` is one token) trained on the
    domain's text, and a random small Llama over it, saved as a model directory."""
    from tokenizers import Tokenizer, decoders, models, pre_tokenizers, trainers
    from transformers import PreTrainedTokenizerFast

    from adaptbench.llm.tiny import CHAT_TEMPLATE, SPECIALS, corpus, tiny_model

    tok = Tokenizer(models.BPE())
    tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False, use_regex=True)
    tok.decoder = decoders.ByteLevel()
    trainer = trainers.BpeTrainer(vocab_size=2048, special_tokens=list(SPECIALS), show_progress=False,
                                  initial_alphabet=pre_tokenizers.ByteLevel.alphabet())
    tok.train_from_iterator(corpus(domain) + [f"Action: {a}" for a in ACTIONS] * 20, trainer=trainer)
    fast = PreTrainedTokenizerFast(tokenizer_object=tok, bos_token="<|bos|>", eos_token="<|end|>",
                                   pad_token="<|pad|>", chat_template=CHAT_TEMPLATE, padding_side="left",
                                   model_max_length=16384)
    out = tmp_path_factory.mktemp("spaced")
    fast.save_pretrained(out)
    tiny_model(fast, seed=3).save_pretrained(out)
    return out


@pytest.fixture(scope="module")
def spaced_backend(spaced):
    from adaptbench.llm.hf import TransformersBackend

    return TransformersBackend(str(spaced), batch_size=4)


def _planner_text(domain, backend, agent="planner"):
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder

    ep, made = play(domain)
    from adaptbench.llm.policies import AGENTS

    return render(backend.tokenizer, PromptBuilder(domain, AGENTS[agent]).prompt(ep.view(), made_after=made))


def test_the_leading_space_tokenizer_is_healed_and_the_tiny_one_is_not(domain, spaced_backend, backend):
    from adaptbench.llm.boundary import split_tail

    text = _planner_text(domain, spaced_backend)
    assert text.endswith("Action: ")
    h = split_tail(spaced_backend.tokenizer, text)
    assert (h.head, h.tail) == (text[:-1], " ")
    tiny_text = _planner_text(domain, backend)
    assert split_tail(backend.tokenizer, tiny_text).tail == ""  # "Action: " is a boundary there
    assert split_tail(spaced_backend.tokenizer, "no space at the end").tail == ""


def test_the_model_reads_the_tokens_of_the_whole_line(domain, spaced_backend):
    """The healed prompt's tokens followed by the completion's are the tokens of the text `...Action: Look
    for eggs` (what the model reads in its history); the raw prompt's are not."""
    from adaptbench.llm.backend import Request
    from adaptbench.llm.boundary import heal

    tok = spaced_backend.tokenizer
    text = _planner_text(domain, spaced_backend)
    for action in ACTIONS:
        whole = spaced_backend.encode(text + action)
        raw = spaced_backend.encode(text)
        assert whole[:len(raw)] != raw  # the bug: the prompt ends on a lone space token
        req, tail = heal(tok, Request(text, "start: /.+/\n"))
        head = spaced_backend.encode(req.prompt)
        assert whole[:len(head)] == head and tok.decode(whole[len(head):]) == tail + action
        assert tok.convert_ids_to_tokens(whole[len(head)])[0] == "Ġ"  # the next word carries the space


def test_constrained_first_token_is_the_unconstrained_distribution_restricted(domain, spaced_backend):
    """The processor's masked first-step distribution equals the model's own after `...Action:`,
    restricted to the grammar's tokens and renormalised; those tokens are the space-led words of the
    actions (` Look`, ` Open`, ...), never a bare word."""
    import torch

    from adaptbench.llm.backend import Request
    from adaptbench.llm.boundary import heal
    from adaptbench.llm.constrained import GrammarProcessor
    from adaptbench.llm.policies import LLMPolicy

    b, tok = spaced_backend, spaced_backend.tokenizer
    ep, made = play(domain)
    policy = LLMPolicy(b, domain, "planner")
    grammar = policy._prepare(ep.view())[1]
    text = _planner_text(domain, b)
    req, _ = heal(tok, Request(text, grammar))
    ids = torch.tensor([b.encode(req.prompt)])
    with torch.no_grad():
        logits = b.model(input_ids=ids).logits[:, -1].float()
    proc = GrammarProcessor(b.matchers, [req.grammar], tok.eos_token_id, b.vocab)
    masked = proc(ids, logits.clone())
    allowed = torch.isfinite(masked[0])
    constrained = torch.softmax(masked[0], -1)
    free = torch.softmax(logits[0], -1)
    restricted = torch.where(allowed, free, torch.zeros_like(free))
    restricted /= restricted.sum()
    assert torch.allclose(constrained, restricted, atol=1e-6)
    words = {tok.convert_ids_to_tokens(int(i)) for i in torch.nonzero(allowed).flatten()}
    for action in ("Look for eggs", "Open fridge_0", "Declare Done"):
        first = b.encode(text + action)[len(ids[0])]
        assert allowed[first], action  # the natural first token of each action is allowed
    assert words and all(w.startswith("Ġ") for w in words)  # every allowed token begins with the space


@pytest.mark.parametrize("agent", ["planner", "react", "always-ask-llm"])
def test_policies_generate_actions_after_the_healed_prefix(domain, spaced_backend, agent):
    from adaptbench.llm.policies import LLMPolicy

    ep, _ = play(domain)
    policy = LLMPolicy(spaced_backend, domain, agent, every=1)
    d = policy.act(ep.view())
    assert d.action == d.action.lstrip() and d.stats["parsed"] is not None and d.stats["accepted"]
    assert d.stats["healed"] == " "
    if agent == "always-ask-llm":
        assert d.action.startswith("Ask ")  # the forced question is healed too
    if agent == "react":
        assert "thought" not in d.stats or not d.stats["thought"].startswith(" ")


def test_unconstrained_request_keeps_one_line(spaced_backend):
    from adaptbench.llm import boundary
    from adaptbench.llm.backend import Request

    out = boundary.generate(spaced_backend, [Request("<|user|>\nHi<|end|>\n<|assistant|>\nThought: ", None,
                                                     ("\n",), 12)])[0]
    assert out.accepted is None and "\n" not in out.text and not out.text.startswith(" ")


def test_openai_backend_gets_the_healed_prompt_and_grammar(domain, spaced, monkeypatch):
    """The served model receives the prompt's tokens up to `Action:` and a grammar that starts with the
    space; the text that comes back (` Look for eggs`) is returned without it."""
    from adaptbench.llm import boundary
    from adaptbench.llm.backend import Request
    from adaptbench.llm.openai_backend import OpenAIBackend

    b = OpenAIBackend("http://127.0.0.1:9/v1", model="m", tokenizer=str(spaced))
    sent = []

    def post(path, body):
        sent.append(body)
        return {"choices": [{"text": " Look for eggs"}], "usage": {"completion_tokens": 3}}

    monkeypatch.setattr(b, "_post", post)
    text = "<|user|>\nWhat next?<|end|>\n<|assistant|>\nAction: "
    out = boundary.generate(b, [Request(text, 'start: "Look for eggs"\n', (), 8, lambda t: t == "Look for eggs")])[0]
    assert out.text == "Look for eggs" and out.accepted
    assert sent[0]["prompt"] == b.encode(text[:-1])
    assert sent[0]["structured_outputs"]["grammar"].startswith('start: " " adapt_healed_start\n')


def test_score_heals_the_continuations(domain, spaced_backend):
    """Scoring `Look for eggs` after `...Action: ` reads the tokens of the whole line."""
    import math

    from adaptbench.llm import boundary

    b = spaced_backend
    text = _planner_text(domain, b)
    got = boundary.score(b, text, ["Look for eggs"])[0]
    whole = b.encode(text + "Look for eggs")
    head = b.encode(text[:-1])
    direct = b.score(text[:-1], [" Look for eggs"])[0]
    assert len(got.logprobs) == len(whole) - len(head) + 1 and got.logprobs == direct.logprobs  # + the end token
    assert got.token_ids == direct.token_ids
    assert all(math.isfinite(x) for x in got.logprobs)
