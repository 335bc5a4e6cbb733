"""The tiny tokenizer's two word splits (`adapt model init --words joined|spaced`): spaced gives a word one
token wherever it stands (the user's answer, an id, an action's end), both round-trip every text, and a
model built with either runs constrained rollouts."""

from __future__ import annotations

import json

import pytest

from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS

ANSWER = "I eat breakfast at my standing desk or at the kitchen island. I love avocado as a side."
ACTIONS = ("Move plate_0 to island_0", "Move cup_1 to desk_0", "Look for avocado")


@pytest.fixture(scope="module")
def tokenizers(domain):
    from adaptbench.llm.tiny import WORD_SPLITS, train_tokenizer

    return {w: train_tokenizer(domain, words=w) for w in WORD_SPLITS}


def _shared(tok, answer: str, action: str) -> set:
    """Token ids an action shares with the answer."""
    return set(tok.encode(answer, add_special_tokens=False)) & set(tok.encode(action, add_special_tokens=False))


def test_spaced_words_are_one_token_in_an_answer_an_id_and_an_actions_end(tokenizers):
    spaced, joined = tokenizers["spaced"], tokenizers["joined"]
    for action, word in zip(ACTIONS, ("island", "desk", "avocado"), strict=True):
        (wid,) = spaced.encode(word, add_special_tokens=False)
        assert wid in _shared(spaced, ANSWER, action), action
    # joined: "desk " (with its space) / "desk" before "_0", "avocado " / "avocado" at the end are different tokens
    assert not _shared(joined, ANSWER, ACTIONS[1]) and not _shared(joined, ANSWER, ACTIONS[2])


def test_both_splits_round_trip_prompts_and_actions(domain, tokenizers):
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.runtime.observe import layout
    from adaptbench.runtime.scene import sample_scene
    from adaptbench.runtime.world import World

    text = PromptBuilder(domain, "planner").system(layout(World(domain, sample_scene(domain, 0, True))), [ANSWER])
    for words, tok in tokenizers.items():
        for t in (text, *ACTIONS, 'Ask "Would you like fruit, nuts or avocado on the side?"'):
            assert tok.decode(tok.encode(t, add_special_tokens=False)) == t, words
    assert len(tokenizers["spaced"].encode(text)) > len(tokenizers["joined"].encode(text))


def test_a_spaced_model_rolls_out_under_the_grammar(domain, tmp_path):
    from adaptbench.harness.rollout import Job, rollout
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.tiny import init_tiny

    path = init_tiny(domain, tmp_path / "spaced", words="spaced")
    assert json.loads((path / "tokenizer.json").read_text())["pre_tokenizer"]["pretokenizers"][0]["pattern"] \
        == {"Regex": r"[^\W_]+|_|[^\w\s]+|\s+"}
    out = tmp_path / "r.jsonl"
    rollout([Job("planner", "juan", "eggs", 0)], out, progress=False, domain=domain,
            backend=TransformersBackend(str(path)), steps=3)
    (rec,) = [json.loads(x) for x in out.read_text().splitlines()]
    assert len(rec["steps"]) == 3 and all(s["action"] for s in rec["steps"])


def test_an_unknown_split_is_refused(domain, tmp_path):
    from adaptbench.llm.tiny import init_tiny

    with pytest.raises(ValueError, match="unknown word split 'words'.*joined, spaced"):
        init_tiny(domain, tmp_path / "x", words="words")
