"""`bench/interpolate.py`: a model between two of the same shape, in whole or only in the weights a pattern
names (`--only`)."""

from __future__ import annotations

import pytest

from .bench_scripts import bench_script
from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def _script():
    """The bench script as a module."""
    return bench_script("interpolate")


@pytest.fixture(scope="module")
def shifted(tiny, tmp_path_factory):
    """The tiny model with every weight plus one: B, as far from A (the tiny model) as it can be told."""
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    out = tmp_path_factory.mktemp("shifted")
    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32)
    with torch.no_grad():
        for p in model.parameters():
            p.add_(1.0)
    model.save_pretrained(out)
    AutoTokenizer.from_pretrained(tiny).save_pretrained(out)
    return out


def _weights(path):
    import torch
    from transformers import AutoModelForCausalLM

    return AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32).state_dict()


def test_only_mixes_the_named_weights(tiny, shifted, tmp_path):
    out = tmp_path / "attn"
    assert _script().main(["--a", str(tiny), "--b", str(shifted), "--t", "0.25", "--only", "self_attn",
                           "--out", str(out)]) == 0
    a, mixed = _weights(tiny), _weights(out)
    names = [k for k in a if "self_attn" in k]
    assert names and len(names) < len(a)
    for k in a:
        want = a[k] + 0.25 if "self_attn" in k else a[k]
        assert (mixed[k] - want).abs().max() < 1e-5, k


@pytest.mark.parametrize("t", [0.5, 1.5], ids=["between", "past-b"])
def test_whole_interpolation_moves_every_weight(tiny, shifted, tmp_path, t):
    """Between the models, and past B (a weight above 1 scales A -> B's change: task arithmetic)."""
    out = tmp_path / "mixed"
    assert _script().main(["--a", str(tiny), "--b", str(shifted), "--t", str(t), "--out", str(out)]) == 0
    a, mixed = _weights(tiny), _weights(out)
    assert all((mixed[k] - a[k] - t).abs().max() < 1e-5 for k in a)


@pytest.mark.parametrize(("flags", "message"), [
    (["--t", "1", "--only", "no_such_weight"], "matches no weight name"),
    (["--t", "3.5"], "up to 3"),
], ids=["pattern-names-nothing", "weight-out-of-range"])
def test_bad_settings_are_refused_before_writing(tiny, shifted, tmp_path, capsys, flags, message):
    with pytest.raises(SystemExit) as err:
        _script().main(["--a", str(tiny), "--b", str(shifted), *flags, "--out", str(tmp_path / "x")])
    assert err.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
