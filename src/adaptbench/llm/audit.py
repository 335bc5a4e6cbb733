"""Auditing the LLM persona user like the offline one (`qa.fidelity`): for every preference, probe
questions a planner would ask, and judge each answer against the preference; the same question in the
same state must get the same answer; location probes must not be answered with where things are (an
entity id or a furniture word of the house).

An answer is judged on the content words the question did not contain: a user that repeats the
question ("The robot asks: How do you like your eggs?") names the eggs the question named and says
nothing. Each answer gets one verdict:

- `echo`: no content word beyond the question's (and the prompt's own "the robot asks");
- `non-answer`: "I don't mind", "I'm flexible" and the like, with no word of the preference;
- `hit`: it agrees with the preference: a new content word of the preference's text or of the offline
  user's answer to the same probe (the reference answer), e.g. "whole milk" for juan's eggs;
- `miss`: anything else (an answer about something else).

Word agreement cannot see negation ("no milk, please" would count as naming milk); `--verbose` lists
the misses, and a reader can judge the hits from the answers printed beside them.
"""

from __future__ import annotations

import re
import sys
import time
from dataclasses import dataclass

from ..agents.users import NO_LOCATION, NO_PREFERENCE, OfflineUser, words
from ..compiler.lint import applies_to
from ..qa.fidelity import LOCATION_PROBES, probes
from ..runtime.env import Env
from .user import NO_ANSWER, LLMUser

VERDICTS = ("hit", "echo", "non-answer", "miss")
ECHO_WORDS = frozenset(words("the robot asks asked question answer user"))
FLEXIBLE = re.compile(r"\b(don'?t mind|flexible|no (particular )?preference|whatever|up to you|"
                      r"you (choose|decide|pick)|go with what you think|not sure|don'?t know)\b", re.I)


@dataclass(frozen=True)
class Probe:
    """One probe of the LLM user, what came back and its verdict (`VERDICTS`)."""

    persona: str
    preference: str
    question: str
    answer: str
    verdict: str
    consistent: bool
    reference: str = ""  # the offline user's answer to the same probe

    @property
    def hit(self) -> bool:
        """Whether the answer agrees with the preference."""
        return self.verdict == "hit"


def new_words(question: str, answer: str) -> set:
    """The answer's content words the question did not contain."""
    return words(answer) - words(question)


def preference_words(pref, reference: str = "") -> set:
    """What an answer carrying the preference says: the content words of the preference's text, its
    first-person answer and the reference (offline) answer."""
    ref = "" if reference in (NO_PREFERENCE, NO_LOCATION) else reference
    return words(pref.text) | words(getattr(pref, "answer", "") or "") | words(ref)


def verdict(pref, question: str, answer: str, reference: str = "") -> str:
    """`hit`, `echo`, `non-answer` or `miss` for an answer to a probe about `pref` (see the module)."""
    fresh = new_words(question, answer) - ECHO_WORDS
    if not fresh:
        return "echo"
    if fresh & preference_words(pref, reference):
        return "hit"
    if answer.strip() == NO_ANSWER or FLEXIBLE.search(answer):
        return "non-answer"
    return "miss"


def names(pref, answer: str, question: str = "") -> bool:
    """Whether an answer names a preference with words the question did not supply."""
    return verdict(pref, question, answer) == "hit"


def _ids(text: str) -> set:
    """The lower-case words and entity ids of a text."""
    return set(re.findall(r"[a-z][a-z0-9_]*", text.lower()))


def leaks(env: Env, answer: str, question: str = "") -> bool:
    """Whether an answer tells where things are: an entity id of the scene other than a room's, or a
    word of a furniture id (`fridge`, `cabinet`, `drawer`, ...), not counting the question's own words
    (an echo of "Which cabinet has the mugs?" tells nothing)."""
    toks = _ids(answer) - _ids(question)
    if toks & {e for e, s in env.world.specs.items() if s.kind != "room"}:  # "search the kitchen" tells nothing
        return True
    furniture = {w for e, s in env.world.specs.items() if s.kind == "furniture"
                 for w in re.findall(r"[a-z]+", e) if len(w) > 3}
    return bool(toks & furniture)


def _plan(domain, personas, max_probes):
    """[(persona, preference, task, question)] for every probe of every preference of the personas,
    ordered by persona and task: successive prompts then share everything but the question, which the
    transformers backend reads once (kept session caches are shared by prefix)."""
    out = []
    order = {t.id: i for i, t in enumerate(domain.tasks)}
    for persona in (domain.persona[p] for p in (personas or list(domain.persona))):
        rows = []
        for pref in persona.preferences:
            tasks = [t for t in domain.tasks if applies_to(domain, pref, t)] or list(domain.tasks)
            rows += [(persona, pref, tasks[0], q) for q in probes(pref)[:max_probes]]
        out += sorted(rows, key=lambda r: order[r[2].id])  # stable: preferences keep their order within a task
    return out


class _Ticker:
    """One progress line on stderr per batch of answers (`--quiet` passes None)."""

    def __init__(self, total: int, stream):
        self.total, self.stream, self.done, self.t0 = total, stream, 0, time.perf_counter()

    def tick(self, n: int, note: str) -> None:
        self.done += n
        if self.stream is not None:
            el = time.perf_counter() - self.t0
            eta = el / self.done * (self.total - self.done)
            print(f"audit: {self.done}/{self.total} answers, {el:.0f} s, eta {eta:.0f} s  {note}",
                  file=self.stream, flush=True)


def _answers(domain, backend, asks: list, batch: int, ticker: _Ticker, label) -> list:
    """The LLM user's answer to each (persona, task, question), `batch` users answering in one batched
    generation (`LLMUser.prepare_answers`), each in the task's scene of seed 0."""
    out = []
    for i in range(0, len(asks), batch):
        chunk = asks[i:i + batch]
        users = [LLMUser(backend, domain, persona, task).bind(Env(domain, task.id, persona.id, 0))
                 for persona, task, _ in chunk]
        LLMUser.prepare_answers([(u, q, ()) for u, (_, _, q) in zip(users, chunk, strict=True)])
        got = [u.answer(q) for u, (_, _, q) in zip(users, chunk, strict=True)]
        out += got
        ticker.tick(len(chunk), label(i, got))
    return out


def audit(domain, backend, personas=None, max_probes: int | None = None, progress=sys.stderr,
          batch: int = 8) -> tuple:
    """Probe the LLM user; returns (probes, summary) with the hit rate, the counts of each verdict,
    consistency and location leaks. Answers are generated `batch` at a time; every probe is asked twice,
    the second time in reversed order (so in other batches), and must get the same answer."""
    plan = _plan(domain, personas, max_probes)
    names_ = list(dict.fromkeys(p.id for p, _, _, _ in plan))
    locs = [(domain.persona[pid], domain.tasks[0], q) for pid in names_ for q in LOCATION_PROBES]
    ticker = _Ticker(2 * len(plan) + len(locs), progress)
    asks = [(persona, task, q) for persona, _, task, q in plan]
    refs = [OfflineUser(domain, persona, task).answer(q) for persona, _, task, q in plan]

    def last(i, got):  # the progress line: the batch's last probe and its verdict
        k = i + len(got) - 1
        persona, pref, _, q = plan[k]
        return f"{persona.id}.{pref.id}: {verdict(pref, q, got[-1], refs[k])}"

    answers = _answers(domain, backend, asks, batch, ticker, last)
    again = _answers(domain, backend, asks[::-1], batch, ticker, lambda i, got: "asked again")[::-1]
    out = [Probe(persona.id, pref.id, q, a, verdict(pref, q, a, ref), a == b, ref)
           for (persona, pref, _, q), a, b, ref in zip(plan, answers, again, refs, strict=True)]
    loc_answers = _answers(domain, backend, locs, batch, ticker, lambda i, got: "location probes")
    leaked = sum(leaks(Env(domain, task.id, persona.id, 0), a, q)
                 for (persona, task, q), a in zip(locs, loc_answers, strict=True))
    return out, summarize(out, leaked)


def summarize(out: list, leaked: int = 0) -> dict:
    """The audit's summary: probes, hits, hit rate, each verdict's count, consistency, leaks."""
    hits = sum(p.hit for p in out)
    return {"probes": len(out), "hits": hits, "hit_rate": hits / len(out) if out else 0.0,
            **{v: sum(p.verdict == v for p in out) for v in VERDICTS if v != "hit"},
            "consistent": all(p.consistent for p in out), "inconsistent": sum(not p.consistent for p in out),
            "location_leaks": leaked}
