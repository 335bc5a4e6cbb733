"""adaptbench: the ADAPT benchmark as data — spec compiler, text simulator, verifiers and Reflection-DPO.

One import gives what a user needs; each name is imported on first use, so `import adaptbench` (and the
`adapt` command) stays fast:

    import adaptbench

    domain = adaptbench.load_domain()                                  # the paper's spec, shipped inside
    env = adaptbench.make_env(domain, persona="juan", task="eggs", seed=0)   # the offline user answers
    agent = adaptbench.make_agent("oracle", domain)                    # any name in agent_names()
    episode = adaptbench.run_episode(agent, env, "oracle/juan/eggs/0")
    print(env.evaluate().satisfaction_rate)
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {  # name -> "module:attribute"
    "load_domain": "adaptbench.compiler:load_domain",
    "default_spec": "adaptbench.paper:default_spec",
    "export_spec": "adaptbench.paper:export_spec",
    "Env": "adaptbench.runtime.env:Env",
    "make_env": "adaptbench.runtime.env:make_env",
    "OfflineUser": "adaptbench.runtime.users:OfflineUser",
    "LLMUser": "adaptbench.llm.user:LLMUser",
    "Policy": "adaptbench.harness.policy:Policy",
    "Decision": "adaptbench.harness.policy:Decision",
    "View": "adaptbench.harness.policy:View",
    "make_agent": "adaptbench.harness.registry:make",
    "register_agent": "adaptbench.harness.registry:register",
    "agent_names": "adaptbench.harness.registry:names",
    "run_episode": "adaptbench.harness.episode:run_episode",
    "run_batch": "adaptbench.harness.episode:run_batch",
    "Job": "adaptbench.harness.rollout:Job",
    "rollout": "adaptbench.harness.rollout:rollout",
    "AdaptError": "adaptbench.errors:AdaptError",
    "SpecError": "adaptbench.compiler.diagnostics:SpecError",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    """Import a public name on first use (PEP 562)."""
    target = _LAZY.get(name)
    if target is None:
        raise AttributeError(f"module 'adaptbench' has no attribute '{name}'")
    module, _, attr = target.partition(":")
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(_LAZY))
