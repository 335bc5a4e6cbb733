"""`bench/cook_and_read.py --anchor-kl`: the KL from the frozen start model is taken on the action tokens
only, and is nothing where the model has not moved."""

from __future__ import annotations

from .bench_scripts import bench_script
from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def _script():
    """The bench script as a module."""
    return bench_script("cook_and_read")


def _models(tiny):
    import torch
    from transformers import AutoModelForCausalLM

    return [AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32) for _ in range(2)]


def _episode():
    """A short sequence whose last three tokens are the action (the rest carry no loss)."""
    ids = list(range(5, 17))
    return ids, [-100] * 9 + ids[9:]


def test_the_anchor_is_zero_where_nothing_moved(tiny):
    model, anchor = _models(tiny)
    losses, kls = _script().anchored_episode_terms(model, anchor, [_episode()])
    assert len(losses) == len(kls) == 1
    assert abs(float(kls[0].detach())) < 1e-6
    assert float(losses[0].detach()) > 0


def test_the_anchor_sees_only_the_action_tokens(tiny):
    import torch

    model, anchor = _models(tiny)
    with torch.no_grad():
        model.lm_head.weight.mul_(3.0)  # tied: every next-token distribution moves
    ids, labels = _episode()
    kl_action = float(_script().anchored_episode_terms(model, anchor, [(ids, labels)])[1][0].detach())
    assert kl_action > 1e-4
    more = [-100] * 5 + ids[5:]  # more tokens labelled: a different mean
    kl_more = float(_script().anchored_episode_terms(model, anchor, [(ids, more)])[1][0].detach())
    assert abs(kl_more - kl_action) > 1e-7
    kl = _script().anchored_episode_terms(model, anchor, [(ids, labels)])[1][0]
    kl.backward()
    assert all(p.grad is None for p in anchor.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in model.parameters())
