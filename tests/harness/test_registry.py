"""One agent registry: built-in scripted and model agents by lazy "module:attr" strings, and agents of
other packages through the entry-point group `adaptbench.agents`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from adaptbench.errors import AdaptError
from adaptbench.harness import registry

ROOT = Path(__file__).resolve().parents[2]
SMALL = ROOT / "tests" / "spec_small"

PLUGIN = '''
from adaptbench.harness.policy import Decision, Policy


class LookThenDone(Policy):
    """A third-party agent: looks for eggs once, then declares done."""

    def __init__(self, domain):
        self.domain = domain

    def act(self, view):
        return Decision("Look for eggs" if not view.history else "Declare Done")
'''


def _plugin(tmp_path: Path) -> Path:
    """A tiny installed distribution (module + dist-info with entry_points.txt) to put on sys.path."""
    site = tmp_path / "site"
    (site / "thirdparty_agents-0.1.dist-info").mkdir(parents=True)
    (site / "thirdparty_agents.py").write_text(textwrap.dedent(PLUGIN))
    info = site / "thirdparty_agents-0.1.dist-info"
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: thirdparty-agents\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[adaptbench.agents]\nlook-then-done = thirdparty_agents:LookThenDone\n")
    return site


def _adapt(args: list, site: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "adaptbench.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def test_a_third_party_agent_from_the_entry_point_group_is_listed_and_runs(tmp_path):
    site = _plugin(tmp_path)
    help_text = _adapt(["rollout", "--help"], site, tmp_path).stdout
    assert "look-then-done (from thirdparty-agents)" in " ".join(help_text.split())
    assert "oracle (privileged" in " ".join(help_text.split())
    r = _adapt(["rollout", "--spec", str(SMALL), "--agent", "look-then-done,never-ask", "--personas", "all",
                "--tasks", "all", "--seeds", "0", "--out", "r.jsonl", "--quiet"], site, tmp_path)
    assert r.returncode == 0, r.stderr
    recs = {(x["agent"], x["persona"]): x for x in map(json.loads, (tmp_path / "r.jsonl").read_text().splitlines())}
    mine = [x for (agent, _), x in recs.items() if agent == "look-then-done"]
    assert len(mine) == 2 and all([s["action"] for s in x["steps"]] == ["Look for eggs", "Declare Done"] for x in mine)
    assert all(x["agent_config"] == {"agent": "look-then-done", "user": "offline", "max_steps": 50} for x in mine)
    assert _adapt(["rollout", "--spec", str(SMALL), "--agent", "look-then-done", "--seeds", "0", "--out", "r.jsonl",
                   "--quiet"], site, tmp_path).stdout.startswith("0 episode(s) run, 2 already")  # resumes


def test_the_builtin_agents_are_registered_by_kind_and_made_lazily(small_domain):
    names = registry.names()
    assert names[:3] == ["oracle", "never-ask", "always-ask"] and "planner" in names
    assert registry.spec("oracle").kind == "scripted" and registry.spec("planner").kind == "model"
    policy = registry.make("never-ask", small_domain)
    assert policy.name == "never-ask" and policy.config() == {"agent": "never-ask"}
    with pytest.raises(ValueError, match="needs a backend"):
        registry.make("planner", small_domain)


def test_an_unknown_agent_is_an_adapt_error_with_exit_code_2_naming_the_choices():
    with pytest.raises(registry.UnknownAgent) as info:
        registry.spec("nope")
    assert isinstance(info.value, AdaptError) and isinstance(info.value, KeyError)
    assert info.value.exit_code == 2 and "choose from: oracle, never-ask" in str(info.value)


def test_register_takes_a_lazy_module_attr_string(small_domain, monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    registry.register("lazy-never", "adaptbench.agents.scripted:NeverAsk", description="the same, renamed")
    assert registry.make("lazy-never", small_domain).config() == {"agent": "lazy-never"}
    with pytest.raises(ValueError, match="module:attr"):
        registry.register("bad", "no_colon_here")
