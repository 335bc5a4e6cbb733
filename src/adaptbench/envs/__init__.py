"""adaptbench for the RL ecosystem: one module per interface, all over `session.Session` (the episode
`adapt rollout` runs: same spec, seeds, offline user and verifiers).

- `envs.gym`: Gymnasium, `adaptbench/Breakfast-v0` (registered on import when gymnasium is installed)
- `envs.server` / `envs.client`: the server (`adapt serve-env`): OpenEnv's WebSocket protocol at `/ws`
  (`envs.websocket`) and HTTP routes, requests checked by `envs.wire`, stalled connections closed by
  `envs.connections`; and its HTTP client
- `envs.trl`: an environment class for TRL's `GRPOTrainer(environment_factory=...)` (`adapt train grpo`)
- `envs.verifiers_env`: `load_environment()` for the `verifiers` library (`vf-eval adapt_breakfast`);
  `envs.sse_relay` ends a local server's streams with `data: [DONE]` for it

docs/environments.md has a runnable example of each and the reward definitions.
"""

from __future__ import annotations

import importlib.util

from .session import REWARDS, Outcome, Session

__all__ = ["REWARDS", "Outcome", "Session"]

if importlib.util.find_spec("gymnasium") is not None:
    from .gym import ENV_ID, AdaptEnv, register

    register()
    __all__ += ["ENV_ID", "AdaptEnv"]
