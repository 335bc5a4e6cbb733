"""Shared grammar fixtures: the index, a cache, the fixture corpus replayed state by state, and an
llguidance tokenizer trained locally (byte-level BPE, no download)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from adaptbench.grammars import GrammarCache, build_index
from adaptbench.runtime.env import Env

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = sorted((ROOT / "spec" / "fixtures" / "trajectories").rglob("*.yaml"))  # the shipped spec's fixtures
EXAMPLES = {"toast_coffee.txt": "toast_coffee", "fifty_steps.txt": "eggs"}


@pytest.fixture(scope="session")
def index(domain):
    return build_index(domain)


@pytest.fixture(scope="session")
def cache(index):
    return GrammarCache(index)


def read_example(name: str) -> list:
    """The actions of an examples/ file."""
    text = (ROOT / "examples" / name).read_text()
    return [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]


def _fixture_runs():
    """(label, task, seed, full, actions, {step index: extra actions issued in the same state})."""
    for path in FIXTURES:
        fx = yaml.safe_load(path.read_text())
        full = fx.get("scene", "full" if "seed" not in fx else "sampled") == "full"
        extra: dict = {}
        for m in fx.get("mutations", ()):
            if "replace" in m:  # the new action is issued in the state the old one was
                old, new = m["replace"]
                extra.setdefault(fx["actions"].index(old), []).append(new)
        yield f"{path.parent.name}/{path.stem}", fx["task"], fx.get("seed"), full, fx["actions"], extra
    for name, task in EXAMPLES.items():
        yield f"examples/{name}", task, None, True, read_example(name), {}


def replay_states(domain):
    """For every fixture and example: (label, observed state, [actions issued in that state])."""
    out = []
    for label, task, seed, full, actions, extra in _fixture_runs():
        env = Env(domain, task, seed=None if full else seed, full_scene=full)
        env.reset()
        for i, text in enumerate(actions):
            out.append((label, task, env.observed(), [text, *extra.get(i, [])]))
            env.step(text)
    return out


@pytest.fixture(scope="session")
def states(domain):
    assert FIXTURES, "no trajectory fixtures under spec/fixtures/trajectories"
    return replay_states(domain)


@pytest.fixture(scope="session")
def lltok():
    llguidance = pytest.importorskip("llguidance")
    from tokenizers import Tokenizer, decoders, models, pre_tokenizers, trainers

    tok = Tokenizer(models.BPE())
    tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
    tok.decoder = decoders.ByteLevel()
    trainer = trainers.BpeTrainer(vocab_size=600, special_tokens=["<eos>"],
                                  initial_alphabet=pre_tokenizers.ByteLevel.alphabet())
    corpus = [ln for p in sorted((ROOT / "grammars").rglob("*.lark")) for ln in p.read_text().splitlines()]
    tok.train_from_iterator(corpus, trainer)
    return llguidance.LLTokenizer(tok.to_str(), eos_token=tok.token_to_id("<eos>"))


class LLAcceptor:
    """Whether llguidance's matcher accepts a whole string under a grammar."""

    def __init__(self, lltok, text: str):
        import llguidance

        self.tok = lltok
        grammar = llguidance.LLMatcher.grammar_from_lark(text)
        err = llguidance.LLMatcher.validate_grammar(grammar, lltok)
        assert not err, err
        self.matcher = llguidance.LLMatcher(lltok, grammar)

    def accepts(self, s: str) -> bool:
        """True when the matcher consumes every token of `s` and is then accepting."""
        m = self.matcher.deep_copy()
        ids = self.tok.tokenize_str(s)
        return m.try_consume_tokens(ids) == len(ids) and m.is_accepting()
