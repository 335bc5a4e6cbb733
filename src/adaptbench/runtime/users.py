"""The offline user: answers `Ask "..."` from the persona's preferences, deterministically.

It picks the preferences whose topics (and text) best match the question, preferring those that
apply to the current task, and answers in the first person. It never says where objects are,
says so when it has no preference, and gives the same answer to the same question.
"""

from __future__ import annotations

import re

from ..compiler.model import CompiledDomain, Persona, Preference, Task

_STOP = frozenset((
    "a an the of to in on for and or with do does did you your i me my would like prefer is are be it this "
    "that any what which how should want have has there some about breakfast please food dish make made "
    "use also get take").split())
_WHERE = r"\bwhere (is|are|can i find|do you keep|would i find|should i look)\b|\b(located|locate)\b|\bfind the\b"
NO_PREFERENCE = "I don't have a particular preference about that; go with what you think is best."
NO_LOCATION = ("I'm not sure where things are kept; please look around and search the kitchen. "
               "I can tell you how I like my breakfast, though.")


def location_question(domain: CompiledDomain) -> re.Pattern:
    """What makes a question one about where things are: `where is ...`, or `which <storage noun>` with the
    engine's `location_words` (cabinet, drawer ...). Built once per domain."""
    def build(d: CompiledDomain) -> re.Pattern:
        nouns = "|".join(re.escape(w) for w in d.engine.location_words)
        which = rf"|\bwhich ({nouns})\b" if nouns else ""
        return re.compile(_WHERE + which, re.I)
    return domain.derived("users.location_question", build)


def words(text: str) -> set:
    """Content words of a text, lower-cased and crudely singularised."""
    out = set()
    for w in re.findall(r"[a-z]+", text.lower()):
        if w in _STOP or len(w) < 3:
            continue
        out.add(singular(w))
    return out


def singular(w: str) -> str:
    """A crude singular: berries -> berry, tomatoes -> tomato, eggs -> egg."""
    if len(w) > 4 and w.endswith("ies"):
        return w[:-3] + "y"
    if len(w) > 4 and w.endswith("oes"):
        return w[:-2]
    if w.endswith("s") and not w.endswith("ss") and len(w) > 3:
        return w[:-1]
    return w


def _score(question: set, pref: Preference) -> float:
    topic_words = set().union(*(words(t) for t in pref.topics)) if pref.topics else set()
    return 2.0 * len(question & topic_words) + 0.5 * len(question & words(pref.text))


class OfflineUser:
    """A deterministic persona user built from the spec (no model)."""

    def __init__(self, domain: CompiledDomain, persona: Persona, task: Task | None = None, max_answers: int = 3):
        self.domain, self.persona, self.task = domain, persona, task
        self.max_answers = max_answers
        self._memory: dict[str, str] = {}

    def relevant(self, pref: Preference) -> bool:
        """Whether a preference's scope covers the current task."""
        if self.task is None or pref.rule.scope is None:
            return True
        groups = self.domain.groups
        return any(c in groups.get(t, (t,)) for t in pref.rule.scope.targets for c in self.task.components)

    def pick(self, question: str) -> list:
        """The preferences a question is about, best first."""
        q = words(question)
        scored = [(_score(q, p) + (0.75 if self.relevant(p) else 0.0), i, p)
                  for i, p in enumerate(self.persona.preferences)]
        scored = [s for s in scored if s[0] >= 2.0]
        scored.sort(key=lambda s: (-s[0], s[1]))
        if not scored:
            return []
        best = scored[0][0]
        return [p for s, _, p in scored[: self.max_answers] if s >= best - 1.0]

    def answer(self, question: str, dialogue: tuple = ()) -> str:
        """First-person answer to a question (same question, same answer). `dialogue` is the
        ((question, reply), ...) so far; this user answers from the question and its own persona, and
        its memory of earlier answers, never from the simulator's state."""
        key = " ".join(sorted(words(question)))
        if key not in self._memory:
            self._memory[key] = self._answer(question)
        return self._memory[key]

    def targets(self, question: str) -> tuple:
        """The ids of the preferences this user answers `question` from (empty for a question about
        where things are, or one that names no preference): what a question is judged by."""
        if location_question(self.domain).search(question):
            return ()
        return tuple(p.id for p in self.pick(question))

    def _answer(self, question: str) -> str:
        if location_question(self.domain).search(question):
            return NO_LOCATION
        prefs = self.pick(question)
        if not prefs:
            return NO_PREFERENCE
        return " ".join(p.answer or first_person(p.text) for p in prefs)


def first_person(text: str) -> str:
    """A plain first-person rendering of a preference text."""
    text = text.strip().rstrip(".")
    lowered = text[0].lower() + text[1:]
    if lowered.startswith(("prefer ", "prefers ")):
        return "I " + lowered.replace("prefers ", "prefer ", 1) + "."
    return f"I'd like this: {lowered}."


def question_targets(env, question: str) -> tuple:
    """The preference ids a question asked in `env` targets, as the offline user's matcher decides:
    what the offline user answered from, and the judge of any other user's questions."""
    return OfflineUser(env.domain, env.persona, env.task).targets(question)
