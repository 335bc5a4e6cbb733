"""The language-model persona user: answers the agent's questions in one line, in the first person,
from the task, the whole state of the house and the persona's preferences (prompt `persona.j2`).

    user = LLMUser(backend, domain, persona, task)
    env = Env(domain, task.id, persona.id, seed, user=user); user.bind(env)

The answer is decoded under a one-line grammar (any characters but a newline) with greedy decoding,
so the same question in the same state gets the same answer.
"""

from __future__ import annotations

from .backend import Request
from .chat import fit, render
from .prompts import Prompt, persona_messages

LINE_GRAMMAR = 'start: LINE\nLINE: /[^\\n]+/\n'


def state_text(world) -> str:
    """Every entity of the house as an indented tree (rooms, furniture, objects in and on them) with
    descriptions and contents: what the persona user sees."""
    from ..runtime.observe import describe

    lines = []

    def walk(eid: str, depth: int) -> None:
        lines.append("  " * depth + "- " + describe(world, eid))
        for child in world.children.get(eid, ()):
            walk(child, depth + 1)

    for room in (e for e, s in world.specs.items() if s.kind == "room" and world.exists(e)):
        walk(room, 0)
    return "\n".join(lines)


def _one_line(text: str) -> bool:
    return bool(text.strip()) and "\n" not in text.strip()


class LLMUser:
    """A persona user backed by a language model."""

    name = "llm"

    def __init__(self, backend, domain, persona, task, env=None, max_tokens: int = 48, budget: int | None = None):
        self.backend, self.domain, self.persona, self.task = backend, domain, persona, task
        self.env, self.max_tokens, self.budget = env, max_tokens, budget
        self.calls: list = []  # (prompt tokens, generated tokens, seconds) per answer

    def bind(self, env) -> LLMUser:
        """Read the house state from `env` (the episode the user belongs to)."""
        self.env = env
        return self

    def config(self) -> dict:
        """What identifies this user (recorded with each episode)."""
        return {"user": "llm", **{f"user_{k}": v for k, v in self.backend.config().items()}}

    def _actions_since_question(self) -> tuple:
        if self.env is None:
            return ()
        out = []
        for e in reversed(self.env.world.trace):
            if e.text.startswith("Ask "):
                break
            out.append(e.text)
        return tuple(reversed(out))

    def prompt(self, question: str, dialogue: tuple = ()) -> Prompt:
        """The persona prompt for a question, earlier turns dropped first when over budget."""
        state = state_text(self.env.world) if self.env is not None else ""
        prefs = tuple(p.text for p in self.persona.preferences)
        actions = self._actions_since_question()
        name = getattr(self.persona, "name", "the user")

        def build(omit: int) -> Prompt:
            return Prompt(persona_messages(name, self.task.text, prefs, state, tuple(dialogue)[omit:],
                                           question, actions), "", omit)

        return fit(self.backend.tokenizer, build, self.budget)

    def answer(self, question: str, dialogue: tuple = ()) -> str:
        """One line, first person."""
        text = render(self.backend.tokenizer, self.prompt(question, dialogue))
        out = self.backend.generate([Request(text, LINE_GRAMMAR, ("\n",), self.max_tokens, _one_line)])[0]
        self.calls.append((out.prompt_tokens, out.tokens, out.stats.get("seconds")))
        return out.text.strip() or "I don't mind; go with what you think is best."
