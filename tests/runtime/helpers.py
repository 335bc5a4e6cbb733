"""Helpers for runtime tests."""

from __future__ import annotations

from adaptbench.runtime.env import Env


def run(domain, actions, task="eggs", persona=None, user=None, **kw):
    """Run actions on a full scene; return (env, results). Every setup action must succeed
    unless it is the last one."""
    env = Env(domain, task=task, persona=persona, full_scene=True, user=user, **kw)
    env.reset()
    results = []
    for a in actions:
        results.append(env.step(a))
    return env, results


def setup_ok(domain, setup, action, **kw):
    """Run `setup` (all must succeed), then `action`; return its result and the env."""
    env, results = run(domain, list(setup) + [action], **kw)
    for text, r in zip(setup, results[:-1], strict=False):
        assert r.ok, f"setup step {text!r} failed: {r.observation}"
    return results[-1], env
