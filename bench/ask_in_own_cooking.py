"""The student's own cooking with the oracle's questions in it: episodes to teach a cook to ask.

    python bench/ask_in_own_cooking.py --model student --personas juan,sarah --tasks all --seeds 130-131 \\
        --out runs/own-asks.jsonl [--batch 16] [--question-set bank]

Every earlier way of teaching the shipped student to ask fine-tuned it on the oracle-ask agent's episodes,
the oracle's cooking step by step unlike the student's, and lost half its cooking within 50 updates
(docs/training.md, twenty-first session; the twenty-second found the learning rate to blame for most of it).
This agent (`planner-oracle-asks`) writes episodes in which the question is the only new thing: the student
(the planner prompt) acts at every step, except where the privileged oracle, looking at the same state, would
act on a choice that one of this persona's preferences decided. There the oracle's question for that
choice comes first (each question once an episode, `OraclePolicy.questions`: the words oracle-ask uses),
then the oracle's action that realises the choice; every other step is the student's own. An oracle action
that failed once in an episode is not taken over again (the student's state may not allow it), so no
episode loops on a step the oracle cannot make.

The records are ordinary `adapt rollout` records (agent `planner-oracle-asks`, the offline user's real
replies), so `training.pretrain.examples` replays them and `bench/cook_and_read.py --episodes` trains on
them whole, the loss on every action. Not a shipped agent: a measurement (docs/training.md).
"""

from __future__ import annotations

import sys

from adaptbench.harness.policy import Decision, Policy

AGENT = "planner-oracle-asks"


class OwnCookingAsks(Policy):
    """The student's planner, with the oracle's question and action at each choice a preference decided."""

    agent_kind = "model"
    name = AGENT

    def __init__(self, backend, domain, **options):
        from adaptbench.agents.scripted import OraclePolicy
        from adaptbench.llm.policies import LLMPolicy

        self.student = LLMPolicy(backend, domain, agent="planner", **options)
        self.oracle = OraclePolicy(domain)

    def config(self) -> dict:
        """The student's configuration, under this agent's name, with what the oracle takes over."""
        return {**self.student.config(), "agent": self.name,
                "takeover": "the oracle's question, then its action, at each choice a preference decided"}

    def start(self, episode: str, env) -> None:
        """The oracle searches this persona's plan; the student starts afresh."""
        self.student.start(episode, env)
        self.oracle.start(episode, env)

    def end(self, episode: str) -> None:
        """Forget the episode on both sides."""
        self.student.end(episode)
        self.oracle.end(episode)

    def act(self, view) -> Decision:
        """The next action for one episode."""
        return self.act_batch([view])[0]

    def act_batch(self, views) -> list:
        """The student's actions for every view (its state stays in step), each replaced by the oracle's
        where the oracle takes over (`takeover`)."""
        own = self.student.act_batch(views)
        return [self.takeover(v) or d for v, d in zip(views, own, strict=True)]

    def takeover(self, view) -> Decision | None:
        """The oracle's decision at this view, or None to leave the step to the student: an unasked question
        of the choice the oracle's next action realises, else that action when a preference decided the
        choice and it has not failed before in this episode."""
        action, serves = self.oracle.next_step(view)
        said = {t.action for t in view.history}
        for question in self.oracle.questions(view.episode, serves):
            if f'Ask "{question}"' not in said:
                return Decision(f'Ask "{question}"', stats={"takeover": "question"})
        failed = {t.action for t in view.history if not t.ok}
        if self.oracle.preferences(view.episode, serves) and action not in failed:
            return Decision(action, stats={"takeover": "choice"})
        return None


def main(argv=None) -> int:
    """Register the agent and run `adapt rollout --agent planner-oracle-asks` with the arguments given."""
    from adaptbench.cli.main import main as adapt
    from adaptbench.harness.registry import register

    register(AGENT, "ask_in_own_cooking:OwnCookingAsks", "model",
             "the student's planner; the oracle's question and action at each choice a preference decided")
    args = list(sys.argv[1:] if argv is None else argv)
    if "-h" in args or "--help" in args:
        print(__doc__)
        return 0
    return adapt(["rollout", "--agent", AGENT, *args])


if __name__ == "__main__":
    sys.exit(main())
