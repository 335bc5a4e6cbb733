"""The language-model persona user: answers the agent's questions in one line, in the first person,
from the task, the whole state of the house and the persona's preferences (prompt `persona.j2`).

    user = LLMUser(backend, domain, persona, task)
    env = Env(domain, task.id, persona.id, seed, user=user); user.bind(env)

The answer is decoded under a one-line grammar (any characters but a newline) with greedy decoding,
so the same question in the same state gets the same answer.

In a batched rollout the harness (`harness.episode.prepare_answers`) asks, before a round of steps,
every LLM user about to be asked a question to answer it: `LLMUser.prepare_answers` renders each
user's prompt from its episode's state as the step will see it and makes one batched
`backend.generate` for all users sharing a backend (`batch_key`). The answer is kept under its
rendered prompt and `answer` uses it only when the step renders exactly that prompt; anything else
(an answer never prepared, or a prompt that differs) is generated on the spot, as one at a time.
"""

from __future__ import annotations

from . import boundary
from .backend import Completion, Request
from .chat import fit, render
from .prompts import Prompt, persona_messages

LINE_GRAMMAR = 'start: LINE\nLINE: /[^\\n]+/\n'
NO_ANSWER = "I don't mind; go with what you think is best."


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


def user_config(backend) -> dict:
    """What identifies an LLM user on `backend`: the backend's configuration, `user_`-prefixed, at
    temperature 0 (the user answers greedily even when it shares the agent's sampling backend)."""
    own = {k: v for k, v in backend.config().items() if k not in ("temperature", "sample_seed")}
    return {"user": "llm", **{f"user_{k}": v for k, v in {**own, "temperature": 0.0}.items()}}


def _one_line(text: str) -> bool:
    return bool(text.strip()) and "\n" not in text.strip()


class LLMUser:
    """A persona user backed by a language model."""

    name = "llm"

    def __init__(self, backend, domain, persona, task, env=None, max_tokens: int = 48, budget: int | None = None):
        self.backend, self.domain, self.persona, self.task = backend, domain, persona, task
        self.env, self.max_tokens, self.budget = env, max_tokens, budget
        self.calls: list = []  # per answer: (prompt tokens, generated tokens, seconds of its generate call, answers in it)
        self._prepared: dict = {}  # rendered prompt -> (Completion, answers in its call), from `prepare_answers`
        # successive prompts share their opening (persona, task, preferences, the unchanged part of the
        # house): a backend may keep this user's key/value cache between answers
        self.session = f"user/{getattr(persona, 'id', 'persona')}/{getattr(task, 'id', 'task')}/{id(self):x}"

    def bind(self, env) -> LLMUser:
        """Read the house state from `env` (the episode the user belongs to)."""
        self.env = env
        return self

    def config(self) -> dict:
        """What identifies this user (recorded with each episode)."""
        return user_config(self.backend)

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

    def _request(self, text: str) -> Request:
        return Request(text, LINE_GRAMMAR, ("\n",), self.max_tokens, _one_line, session=self.session,
                       temperature=0.0)  # greedy whatever the backend's temperature (it may be the agent's)

    def _rendered(self, question: str, dialogue: tuple) -> str:
        return render(self.backend.tokenizer, self.prompt(question, dialogue))

    def batch_key(self):
        """Users with the same backend answer in one batched generation (`prepare_answers`)."""
        return id(self.backend)

    @staticmethod
    def prepare_answers(asks) -> None:
        """Answer several users' questions in one `generate` call. `asks` is [(user, question, dialogue),
        ...] for users sharing a backend, each bound to the episode about to ask, in the state the step
        will see; each answer is kept for its user's next `answer`, used only if that renders the same
        prompt, and dropped after it."""
        for user, _, _ in asks:
            user._prepared = {}
        texts = [user._rendered(q, d) for user, q, d in asks]
        outs = boundary.generate(asks[0][0].backend, [user._request(t) for (user, _, _), t in zip(asks, texts, strict=True)])
        for (user, _, _), text, out in zip(asks, texts, outs, strict=True):
            user._prepared[text] = (out, len(asks))

    def answer(self, question: str, dialogue: tuple = ()) -> str:
        """One line, first person (the prepared answer when there is one for exactly this prompt)."""
        text = self._rendered(question, dialogue)
        out, batch = self._prepared.pop(text, (None, 1))
        self._prepared.clear()  # an answer prepared for another prompt is stale once the user has answered
        if out is None:
            out = boundary.generate(self.backend, [self._request(text)])[0]
        self.calls.append((out.prompt_tokens, out.tokens, out.stats.get("seconds"), batch))
        return _reply(out)


def _reply(out: Completion) -> str:
    return out.text.strip() or NO_ANSWER
