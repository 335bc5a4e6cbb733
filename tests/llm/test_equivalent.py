"""`--skip-equivalent`: a student's action that the oracle's plan finishes as well as its own is no correction."""

from __future__ import annotations

import pytest

from adaptbench.training.equivalent import Outcome, as_good, equivalent, fork, outcome

from .conftest import SKIP_MODELS, play


def _started(domain, task, steps=(), persona="juan", seed=100):
    from adaptbench.training.relabel import ScriptedTeacher

    ep, _ = play(domain, task, persona, seed, steps)
    teacher = ScriptedTeacher(domain)
    teacher.start(ep.id, ep.env)
    return ep, teacher


def test_fork_is_the_same_state(domain):
    ep, _ = play(domain, "tea_eggs", seed=100, steps=('Ask "Would you like toast on the side?"', "Look for bread",
                                                       "Look for kiwi", "Open unicorn_0"))
    copy = fork(ep)
    trace = lambda e: [(x.text, x.ok, x.observation, x.reply) for x in e.env.world.trace]  # noqa: E731
    assert trace(copy) == trace(ep) and copy.view().made == ep.view().made and copy.id == ep.id
    assert copy.env.evaluate().as_dict() == ep.env.evaluate().as_dict()
    from adaptbench.harness.policy import Decision

    copy.apply(Decision("Look for eggs"))
    assert len(ep.history) == 4 and ep.env.world.step == 4  # the copy's steps never reach the original


def test_a_plan_step_out_of_order_is_equivalent_and_a_wasted_or_failed_one_is_not(domain):
    ep, teacher = _started(domain, "tea_eggs")
    a_t = teacher.action(ep.view())
    assert a_t.startswith("Pour water") and a_t != "Look for bread"
    assert equivalent(ep, "Look for bread", a_t, teacher.policy)  # toast comes later in the plan: no loss
    for wasted in ("Look for kiwi", "Open unicorn_0", 'Ask "Would you like toast on the side?"'):
        assert not equivalent(ep, wasted, a_t, teacher.policy)  # a step more to the same end
    assert ep.env.world.step == 0 and not ep.history  # nothing was stepped on the episode itself


def test_an_action_that_loses_a_preference_is_not_equivalent(domain):
    ep, teacher = _started(domain, "eggs", steps=("Look for pan",))
    a_t = teacher.action(ep.view())
    other = "Move pan_0 to stove_0" if a_t != "Move pan_0 to stove_0" else "Move pan_1 to stove_0"
    mine, its = outcome(ep, other, teacher.policy), outcome(ep, a_t, teacher.policy)
    assert its.satisfied > mine.satisfied and not as_good(mine, its)


@pytest.mark.parametrize(("mine", "good"), [
    (Outcome(3, 1, 2, 20), True), (Outcome(4, 1, 2, 20), True), (Outcome(3, 1, 2, 21), False),
    (Outcome(2, 1, 2, 19), False), (Outcome(3, 2, 2, 20), False), (Outcome(3, 1, 1, 20), False),
])
def test_as_good_on_every_count(mine, good):
    assert as_good(mine, Outcome(3, 1, 2, 20)) is good


@SKIP_MODELS
def test_builder_skips_equivalent_steps_only_when_asked(backend, domain, tmp_path):
    from dataclasses import replace

    from adaptbench.training.data import Builder, DataSettings
    from adaptbench.training.dataset import PairStore
    from adaptbench.training.relabel import student_policy

    student = student_policy(backend, domain)
    own = student.act_batch
    plays = {0: "Look for bread"}  # a later step of the plan first, then a step that fails
    student.act_batch = lambda views: [replace(d, action=plays.get(v.step, "Open unicorn_0"))
                                       for d, v in zip(own(views), views, strict=True)]
    settings = DataSettings(0, ("juan",), ("tea_eggs",), (100,), questions="topics", max_length=None, width=1,
                            max_steps=3)
    off = PairStore(tmp_path / "off")
    Builder(domain, student, settings, off, "tiny").run()
    assert [r["skip_reason"] for r in off.rows if r["kind"] == "skipped"] == []
    on = PairStore(tmp_path / "on")
    Builder(domain, student, replace(settings, skip_equivalent=True), on, "tiny").run()
    assert [r["skip_reason"] for r in on.rows] == ["equivalent", None, None]
    assert [r["kind"] != "skipped" for r in on.rows[1:]] == [True, True]
