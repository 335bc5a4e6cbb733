"""Teacher relabelling and reflection for Reflection-DPO (Algorithm 1).

- `ScriptedTeacher`: the privileged oracle planning from the student's own state (its plan searched once per
  episode at `start`, then re-executed from the view's known world at every step), so a^t is what the
  teacher would do next in the state the student reached. `proposals` also names why: the ids of the
  persona's preferences that decided the choice a^t realises (`OraclePolicy.proposal`) and the teacher's
  thought in the paper's form ("Since Ron prefers ..., my next step is ..."); () and None for a step that
  serves no preference.
- `LLMTeacher` (`--teacher-model DIR`): a language model with the privileged `teacher` prompt (the persona's
  preferences, and at every step a reminder of those the verifier finds unmet so far on the student's
  trajectory) proposing a^t for the student's state under the state's grammar, batched over episodes.
- `reflection_request`: the reflection prompt (`prompts.reflection_messages`) as a generation under the
  grammar's Ask-only rule: the student proposes the question q.
- `Proposal.questions` (`--questions choices`): for a model too small to write questions, the question
  `oracle-ask` asks at the choice a^t realises (the choice a preference decided), in the words a student
  taught on oracle-ask's episodes asks it.
- `preference_question`: for a model too small to write questions, a question about the preference the
  teacher named, built from its topics like `adapt users check`'s probes; `topic_question`, when the
  teacher named none: the topic (domain-wide, not the persona's) sharing most words with a^t.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..agents.scripted import OraclePolicy
from ..harness.policy import Turn
from ..llm.backend import Request
from ..llm.chat import render
from ..llm.prompts import ACTION_PREFIX, Prompt, reflection_messages
from ..runtime.users import words

QUESTION = re.compile(r'^Ask\s+"(.*)"\s*$', re.S)


@dataclass(frozen=True)
class Proposal:
    """The teacher's a^t for a state, the ids of the persona's preferences it serves (() when none or not
    known) and the teacher's thought naming them (None without preferences)."""

    action: str
    preferences: tuple = ()
    reason: str | None = None
    questions: tuple = ()  # the questions of the choices a^t realises that a preference decided (oracle-ask's)


def proposals(teacher, views) -> list:
    """A `Proposal` for every view: the teacher's own `proposals`, or its `actions` with no reasons."""
    if hasattr(teacher, "proposals"):
        return teacher.proposals(views)
    return [Proposal(a) for a in teacher.actions(views)]


class ScriptedTeacher:
    """The scripted oracle as a relabeller: `start(episode, env)`, then `action(view)` or `proposal(view)`
    for any state."""

    name = "oracle"
    model = None

    def __init__(self, domain):
        self.policy = OraclePolicy(domain)
        self._personas: dict = {}

    def start(self, episode: str, env) -> None:
        """Search the episode's best plan (privileged: reads the persona, simulates the scene)."""
        self.policy.start(episode, env)
        self._personas[episode] = env.persona

    def proposal(self, view) -> Proposal:
        """The teacher's next action from the student's state (Declare Done when the plan is exhausted),
        the preferences it serves and the thought that names them."""
        action, serves = self.policy.next_step(view)
        ids = self.policy.preferences(view.episode, serves)
        persona = self._personas[view.episode]
        prefs = [p for p in persona.preferences if p.id in ids]
        return Proposal(action, ids, thought(persona.name, prefs, action) if prefs else None,
                        self.policy.questions(view.episode, serves) if ids else ())

    def action(self, view) -> str:
        """The teacher's next action from the student's state."""
        return self.proposal(view).action

    def proposals(self, views) -> list:
        """A `Proposal` for every view."""
        return [self.proposal(v) for v in views]

    def actions(self, views) -> list:
        """a^t for every view."""
        return [p.action for p in self.proposals(views)]

    def end(self, episode: str) -> None:
        """Forget the episode's plan."""
        self.policy.end(episode)
        self._personas.pop(episode, None)


_PRONOUNS = ("he", "she", "they")


def since(name: str, text: str) -> str:
    """A preference text as the clause after "Since" in the paper's reflection prompt ("Since Ron prefers
    his coffee to be served first ..."): the persona named for a pronoun, "prefers" for a bare "Prefer",
    and any other text quoted after "<name> prefers this:"."""
    t = text.strip().rstrip(".")
    first, _, rest = t.partition(" ")
    if first.lower() in _PRONOUNS or first == name:
        return f"{name} {rest}"
    if first.lower() in ("prefer", "prefers"):
        return f"{name} prefers {rest}"
    if first == "Does":
        return f"{name} does {rest}"
    return f'{name} prefers this: "{t}"'


def thought(name: str, preferences, action: str) -> str:
    """The teacher's thought for a^t in the paper's form: "Since <persona> prefers <preference>, my next
    step is <a^t>." (each preference the action serves, joined)."""
    clauses = " and since ".join(since(name, p.text) for p in preferences)
    return f"Since {clauses}, my next step is {action}."


class LLMTeacher:
    """A language-model teacher over its own backend: the `teacher` agent (privileged prompt, unmet
    preferences reminded each step, the grammar of the student's state). Its episodes are keyed apart from
    the student's (`/teacher`), so a backend shared with the student never mixes their cached prefixes."""

    name = "llm"

    def __init__(self, backend, domain, model: str, **kw):
        from ..llm.policies import LLMPolicy

        self.policy = LLMPolicy(backend, domain, "teacher", **kw)
        self.model = model

    @staticmethod
    def _key(episode: str) -> str:
        return f"{episode}/teacher"

    def start(self, episode: str, env) -> None:
        """Keep the episode's env: the persona's preferences and the verdicts of the student's steps so far."""
        self.policy.start(self._key(episode), env)

    def proposals(self, views) -> list:
        """A `Proposal` for every view: a^t without preferences (the LLM names none)."""
        return [Proposal(a) for a in self.actions(views)]

    def actions(self, views) -> list:
        """a^t for every view: one batched generation."""
        if not views:
            return []
        from dataclasses import replace

        return [d.action for d in self.policy.act_batch([replace(v, episode=self._key(v.episode)) for v in views])]

    def end(self, episode: str) -> None:
        """Forget the episode."""
        self.policy.end(self._key(episode))


def reflection_request(student, view, student_action: str, teacher_action: str, made_after=(),
                       reason: str | None = None) -> Request:
    """The generation that asks the student which question would have let it predict `teacher_action`
    (`reason`: the teacher's thought, shown as the paper's prompt shows it)."""
    msgs = reflection_messages(student.builder, view, student_action, teacher_action, made_after, reason)
    text = render(student.backend.tokenizer, Prompt(msgs, ACTION_PREFIX))
    grammar = student.grammars.state(view.task, view.observed, student.level, "ask_only").text
    return Request(text, grammar, (), student.max_tokens)


def question_text(action: str) -> str | None:
    """The question inside an `Ask "..."` action (None when it is not one)."""
    m = QUESTION.match(action.strip())
    return m.group(1) if m else None


def topics(domain) -> tuple:
    """Every topic of every persona's preferences, sorted (what the topic proposer chooses from)."""
    return tuple(sorted({t for p in domain.personas for pref in p.preferences for t in pref.topics}))


def topic_question(all_topics: tuple, teacher_action: str, task_text: str) -> str:
    """An Ask action about the topic sharing most words with the teacher's action (then the task)."""
    target, context = words(teacher_action), words(task_text)
    best = max(all_topics, key=lambda t: (len(words(t) & target), len(words(t) & context), -all_topics.index(t)))
    return f'Ask "What would you like for the {best}?"'


def preference_question(pref) -> str:
    """An Ask action about one preference from its topics, as `adapt users check` probes it: "Do you have
    any preference about <topic>, <topic> or <topic>?" (its first three). The offline user answers
    this question from that preference for every preference of the shipped personas (97% of them
    first)."""
    t = list(pref.topics[:3]) or [pref.text.strip().rstrip(".").lower()]
    about = t[0] if len(t) == 1 else f"{', '.join(t[:-1])} or {t[-1]}"
    return f'Ask "Do you have any preference about {about}?"'


def answered_prompt(student, prompt: Prompt, view, question: str, answer: str) -> Prompt:
    """The student's prompt x continued with the question and the user's answer (x, q, answer)."""
    turn = Turn(question, "", True, answer)
    msgs = (*prompt.messages, {"role": "assistant", "content": ACTION_PREFIX + question},
            {"role": "user", "content": student.builder.turn(view.task_text, turn, view.made)})
    return Prompt(msgs, ACTION_PREFIX, prompt.omitted)


def student_policy(backend, domain, **kw):
    """The student: the planner policy whose decisions keep their `Prompt` (the rows' prompt x)."""
    from dataclasses import replace

    from ..llm.policies import LLMPolicy

    class Student(LLMPolicy):
        def _decision(self, prompt, out, force, thought, prep):
            return replace(super()._decision(prompt, out, force, thought, prep), prompt=prompt)

    return Student(backend, domain, "planner", **kw)
