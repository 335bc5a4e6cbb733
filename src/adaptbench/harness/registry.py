"""One registry of agents: scripted, language-model and (later) trained ones, by lazy `"module:attr"`
strings, as Gymnasium's `register`/`make` is. Nothing is imported until an agent is made.

    register("mine", "mypkg.agents:MyPolicy")            # a factory called as factory(domain, **options)
    policy = make("oracle", domain)
    policy = make("planner", domain, backend=backend)    # model agents get the backend handed in
    names()                                              # every agent, built-in and installed

Other packages add agents through the entry-point group `adaptbench.agents` (in their pyproject:
`[project.entry-points."adaptbench.agents"] mine = "mypkg.agents:MyPolicy"`); the factory's
`agent_kind = "model"` attribute says that it takes a `backend` (default: scripted, no backend).
"""

from __future__ import annotations

import contextlib
import importlib
from dataclasses import dataclass, field

from ..errors import AdaptError

GROUP = "adaptbench.agents"
KINDS = ("scripted", "model")


class UnknownAgent(AdaptError, KeyError):
    """An agent name nobody registered."""

    exit_code = 2

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


@dataclass(frozen=True)
class AgentSpec:
    """A registered agent: its name, the factory (`"module:attr"`), its kind (`scripted`, or `model`:
    takes a backend), fixed options passed to the factory and a one-line description."""

    name: str
    entry: str
    kind: str | None = "scripted"  # None: read from the factory's `agent_kind` when it is loaded
    options: dict = field(default_factory=dict)
    description: str = ""

    def load(self):
        """The factory (imports its module)."""
        module, _, attr = self.entry.partition(":")
        obj = importlib.import_module(module)
        for part in attr.split(".") if attr else ():
            obj = getattr(obj, part)
        return obj

    def resolved_kind(self) -> str:
        """`scripted` or `model` (loads a plug-in's factory to read its `agent_kind`)."""
        return self.kind or getattr(self.load(), "agent_kind", "scripted")


_SCRIPTED = "adaptbench.agents.scripted"
_LLM = "adaptbench.llm.policies:LLMPolicy"
_REGISTRY: dict = {}
_PLUGINS: dict = {"loaded": False}


def register(name: str, entry: str, kind: str | None = "scripted", description: str = "", **options) -> None:
    """Register (or replace) the agent `name` made by the factory at `entry` ("module:attr")."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"agent kind must be one of {', '.join(KINDS)} (got '{kind}')")
    if ":" not in entry:
        raise ValueError(f"agent entry '{entry}' is not 'module:attr'")
    _REGISTRY[name] = AgentSpec(name, entry, kind, dict(options), description)


for _name, _cls, _text in (("oracle", "OraclePolicy", "privileged: searches the plan against the persona's verifiers"),
                           ("never-ask", "NeverAsk", "default recipes, no questions"),
                           ("always-ask", "AlwaysAsk", "asks about every choice first"),
                           ("oracle-ask", "OracleAskPolicy", "privileged plan, asks first where it departs from "
                            "the defaults")):
    register(_name, f"{_SCRIPTED}:{_cls}", "scripted", _text)
for _name, _kind in (("planner", "planner"), ("teacher", "teacher"), ("react", "react"),
                     ("never-ask-llm", "never_ask"), ("always-ask-llm", "always_ask")):
    register(_name, _LLM, "model", f"language model, {_kind} prompt, needs --model", agent=_name)


def _load_plugins() -> None:
    """Add the agents other installed packages declare in the entry-point group (once per process)."""
    if _PLUGINS["loaded"]:
        return
    _PLUGINS["loaded"] = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=GROUP):
        if ep.name not in _REGISTRY:
            _REGISTRY[ep.name] = AgentSpec(ep.name, ep.value, None, {}, f"from {ep.dist.name if ep.dist else 'a plug-in'}")


def registry() -> dict:
    """Name -> AgentSpec of every agent, built-in and installed."""
    _load_plugins()
    return dict(_REGISTRY)


def names() -> list:
    """Every agent's name, in registration order."""
    return list(registry())


def spec(name: str) -> AgentSpec:
    """The AgentSpec of `name`; UnknownAgent (exit code 2) naming the choices otherwise."""
    agents = registry()
    if name not in agents:
        raise UnknownAgent(f"unknown agent {name or '(none given)'} (choose from: {', '.join(agents)})")
    return agents[name]


def make(name: str, domain, backend=None, **options):
    """The policy of agent `name` for `domain`. Model agents get `backend` and `options` (e.g. `budget`);
    scripted ones take the domain only. ValueError when a model agent gets no backend."""
    s = spec(name)
    factory = s.load()
    if s.resolved_kind() == "model":
        if backend is None:
            raise ValueError(f"agent '{name}' is a language-model agent: it needs a backend (--model)")
        policy = factory(backend=backend, domain=domain, **s.options, **options)
    else:
        policy = factory(domain, **s.options)
    if getattr(policy, "name", None) != name:
        with contextlib.suppress(AttributeError):  # the registered name is the agent's name in its records
            policy.name = name
    return policy
