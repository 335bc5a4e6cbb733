"""Several agents' policies as one `Policy`, for the batch runner (`batches.run_batched`): each episode
goes to its agent's policy, and each round every policy decides for its own episodes in one call."""

from __future__ import annotations

from .episode import decide_each
from .policy import Policy


class Same(dict):
    """A mapping that gives one value for every key it does not hold (one policy for every agent)."""

    def __init__(self, value):
        super().__init__()
        self.value = value

    def __missing__(self, key):
        return self.value


class ByAgent(Policy):
    """Several agents' policies as one: each episode goes to its agent's policy (the agent is the part
    of the episode id before persona/task/seed: `batches.episode_id`); each round, one `act_batch` per
    policy for its episodes (a policy that does not batch decides per episode, so that one episode's
    exception ends only that episode)."""

    name = "by-agent"

    def __init__(self, policies: dict):
        self.policies = policies  # agent name -> policy

    def _agent(self, episode: str) -> str:
        return episode.rsplit("/", 3)[0]

    def start(self, episode: str, env) -> None:
        """Start the episode on its agent's policy."""
        self.policies[self._agent(episode)].start(episode, env)

    def end(self, episode: str) -> None:
        """End the episode on its agent's policy."""
        self.policies[self._agent(episode)].end(episode)

    def act(self, view):
        """The decision of the view's agent."""
        return self.policies[self._agent(view.episode)].act(view)

    def act_batch(self, views) -> list:
        """One call per policy for its views, answers in the order of `views`."""
        groups: dict = {}
        for i, v in enumerate(views):
            agent = self._agent(v.episode)
            groups.setdefault(agent, (self.policies[agent], []))[1].append(i)
        out = [None] * len(views)
        for policy, rows in groups.values():
            mine = [views[i] for i in rows]
            batched = type(policy).act_batch is not Policy.act_batch
            for i, d in zip(rows, policy.act_batch(mine) if batched else decide_each(policy, mine), strict=True):
                out[i] = d
        return out
