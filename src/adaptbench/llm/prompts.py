"""Prompts: jinja2 templates shipped in `llm/templates/`, rendered from the domain into chat messages with
the standard roles only (system, user, assistant).

    builder = PromptBuilder(domain, "planner")
    prompt = builder.prompt(view)                  # Prompt(messages, prefix="Action: ")
    text = render(tokenizer, prompt)               # through the model's chat template

The system message lists each action template with one example (from the action spec), the behaviour
instructions, what is known about the user and the house layout (rooms and furniture only). The
history alternates the agent's actions (assistant) with the observation and the user's reply (user);
every user message ends with the progress line ("You have not made anything yet." / "So far, you have
made ...") and the task question. `chat.fit` left-truncates the history to a token budget.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import lru_cache

import jinja2

KINDS = ("planner", "teacher", "react", "never_ask", "always_ask")
ACTION_PREFIX = "Action: "
THOUGHT_PREFIX = "Thought: "
ASK_EVERY = 5  # always-ask: force a question when none was asked in the last N actions


@dataclass(frozen=True)
class ActionLine:
    """One entry of the action list: its template (`Move <X> to <Y>`), summary and one example."""

    template: str
    summary: str
    example: str


@dataclass(frozen=True)
class Prompt:
    """Chat messages (dicts with `role` and `content`) and the assistant text the completion
    continues (`prefix`, e.g. "Action: "). `omitted` counts history steps left out to fit a budget."""

    messages: tuple
    prefix: str = ""
    omitted: int = 0
    meta: dict = field(default_factory=dict, compare=False)


@lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    """The jinja2 environment over the packaged templates (strict: a missing variable is an error)."""
    return jinja2.Environment(loader=jinja2.PackageLoader("adaptbench.llm", "templates"),
                              undefined=jinja2.StrictUndefined, autoescape=False,
                              keep_trailing_newline=False, trim_blocks=False)


def fill(name: str, **values) -> str:
    """Render one template (`planner`, `turn`, ...) and strip surrounding blank lines. Renderings with
    hashable values are remembered (each step's prompt repeats the last one's system message and turns)."""
    try:
        return _fill(name, tuple(sorted(values.items())))
    except TypeError:  # an unhashable value
        return _render(name, values)


@lru_cache(maxsize=8192)
def _fill(name: str, items: tuple) -> str:
    return _render(name, dict(items))


def _render(name: str, values: dict) -> str:
    return environment().get_template(f"{name}.j2").render(**values).strip("\n")


def _placeholder(m: re.Match) -> str:
    return f"<{m.group(1).upper()}>"


def action_lines(domain, ask: bool = True) -> tuple:
    """The action list from the action spec: each action's first form as a template with `<X>`
    placeholders, its summary and its example; the Ask entry dropped when `ask` is False."""
    out = []
    for a in domain.actions:
        if a.id == "ask" and not ask:
            continue
        summary = a.summary.strip()
        summary = summary if summary.endswith(".") else summary + "."
        out.append(ActionLine(re.sub(r"\{(\w+)\}", _placeholder, a.forms[0]), summary, a.example))
    return tuple(out)


def progress(made) -> str:
    """The progress line."""
    return f"So far, you have made {'; '.join(made)}." if made else "You have not made anything yet."


class PromptBuilder:
    """Builds the prompts of one agent kind (`KINDS`) for one domain."""

    def __init__(self, domain, kind: str = "planner", user: str = "the user", every: int = ASK_EVERY):
        if kind not in KINDS:
            raise ValueError(f"unknown prompt kind '{kind}' (choose from: {', '.join(KINDS)})")
        self.domain, self.kind, self.user, self.every = domain, kind, user, every
        self.actions = action_lines(domain, ask=kind != "never_ask")
        self.prefix = THOUGHT_PREFIX if kind == "react" else ACTION_PREFIX

    def system(self, layout: str, preferences=(), prior: str = "") -> str:
        """The system message."""
        return fill(self.kind, user=self.user, actions=self.actions, layout=layout, prior=prior,
                    preferences=tuple(preferences), every=self.every)

    def turn(self, task: str, turn=None, made=(), unmet=(), force_ask: bool = False, omitted: int = 0) -> str:
        """A user message: the observation of `turn` (None for the opening message), the user's reply,
        the progress line and the task question."""
        return fill("turn", first=turn is None, observation=getattr(turn, "observation", ""),
                    reply=getattr(turn, "reply", ""), made=tuple(made), unmet=tuple(unmet), force_ask=force_ask,
                    omitted=omitted, task=task)

    def messages(self, view, preferences=(), prior: str = "", made_after=(), unmet=(),
                 force_ask: bool = False, omit: int = 0) -> tuple:
        """The chat messages for a view. `made_after[i]` is the dishes made after history step i (the
        progress line of that step; the view's `made` for the last); `omit` drops the oldest steps."""
        history = tuple(view.history)
        msgs = [{"role": "system", "content": self.system(view.layout, preferences, prior)}]
        first_last = len(history) == omit
        msgs.append({"role": "user", "content": self.turn(
            view.task_text, None, view.made if first_last else (), unmet if first_last else (),
            force_ask and first_last, omit)})
        for i in range(omit, len(history)):
            last = i == len(history) - 1
            made = view.made if last else (made_after[i] if i < len(made_after) else ())
            msgs.append({"role": "assistant", "content": ACTION_PREFIX + history[i].action})
            msgs.append({"role": "user", "content": self.turn(
                view.task_text, history[i], made, unmet if last else (), force_ask and last)})
        return tuple(msgs)

    def prompt(self, view, omit: int = 0, **kw) -> Prompt:
        """The prompt for a view (see `messages`), continued with the kind's prefix."""
        prefix = ACTION_PREFIX if kw.get("force_ask") else self.prefix
        return Prompt(self.messages(view, omit=omit, **kw), prefix, omit)


def persona_messages(user: str, task: str, preferences, state: str, dialogue=(), question: str = "",
                     actions=()) -> tuple:
    """The persona user's messages: the system message (task, preferences, the house state), the
    earlier questions and answers, and the robot's question with its actions since the last one."""
    msgs = [{"role": "system", "content": fill("persona", user=user, task=task,
                                               preferences=tuple(preferences), state=state)}]
    for q, a in dialogue:
        msgs.append({"role": "user", "content": fill("persona_turn", actions=(), question=q)})
        msgs.append({"role": "assistant", "content": a})
    msgs.append({"role": "user", "content": fill("persona_turn", actions=tuple(actions), question=question)})
    return tuple(msgs)


def reflection_messages(builder: PromptBuilder, view, student: str, teacher: str, made_after=(),
                        reason: str | None = None) -> tuple:
    """The reflection prompt: its system message, the student's history, and the question what the
    robot could have asked to predict the teacher's action. `reason` is the teacher's thought ("Since
    Ron prefers ..."), shown as the paper's prompt shows it: "because if the robot knew the user better,
    it would have thought that '<reason>'"."""
    history = builder.messages(view, made_after=made_after)[1:]
    system = fill("reflection_system", user=builder.user, task=view.task_text, layout=view.layout)
    last = dict(history[-1])
    last["content"] += "\n\n" + fill("reflection", student=student, teacher=teacher, user=builder.user,
                                      reason=reason or "")
    return ({"role": "system", "content": system}, *history[:-1], last)
