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


def test_hard_pairs_draw_by_loss_and_keep_every_pair_in_reach():
    import random

    import torch

    s = _script()
    sampler = s.HardPairs([0.0, 0.0, 10.0, 0.0], random.Random(0), floor=0.05, rescore=2)
    draws = [sampler.draw(1)[0] for _ in range(400)]
    assert draws.count(2) > 300 and len(set(draws)) > 1  # the hard pair mostly, the others through the floor
    assert sorted(sampler.draw(4)) == [0, 1, 2, 3]  # distinct indices, never more than there are pairs
    sampler.update([2, 0], [torch.tensor(0.5), torch.tensor(0.25), torch.tensor(1.0), torch.tensor(2.0)])
    assert sampler.losses == [3.0, 0.0, 0.75, 0.0]
    others = sampler.others([0, 1])
    assert sorted(others) == [2, 3]


def test_hard_sampling_needs_the_contrast_loss():
    import random

    import pytest

    s = _script()
    args = s.arguments(["--out", "x", "--episodes", "e.jsonl", "--rows", "r.jsonl", "--pair-sampling", "hard"])
    with pytest.raises(SystemExit, match="takes --row-loss contrast"):
        s.make_sampler(args, None, [], random.Random(0))
    assert s.make_sampler(s.arguments(["--out", "x", "--episodes", "e", "--rows", "r"]), None, [], None) is None
