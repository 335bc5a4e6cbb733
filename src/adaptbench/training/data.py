"""`adapt train data`: Reflection-DPO's dataset (Algorithm 1, DAgger-style).

Rollouts follow the student (batched over episodes through the backend) for at most `max_steps` steps
(50, the paper's budget); at each step the privileged teacher proposes a^t from the student's state; steps
where both act the same (same parsed action) are skipped (and, only when asked, steps after N failures in a
row: `skip_after_failures`, this project's option, not the paper's); otherwise the student reflects (or the
topic proposer asks), the user answers, the row's prompt x is fitted to `max_length` keeping every question
and answer (`rows.fit_prompt`), P(a^t|x), P(a^t|x,q,answer), P(a^s|x) are scored on exactly that x through
the backend's scoring primitive (`score.steps_probabilities`: the asked steps of a batch in one call, so a
served backend has them all in flight), and the decision rule (`decide`) picks the chosen completion. The
rejected answer (the student's own) keeps the ids the student generated (`rejected_token_ids`,
`training.ids`). With `follow_questions` (ours) the rollout asks the question a row chose in place of the
student's action, so later rows are corrections made with its answer known, and a question the episode
already asked is never chosen again. Rows go to `pairs.jsonl` as they are made. The student runs on either backend: a local
model or a served engine (`--backend openai`), the rows the same in meaning (same ids, same scoring).

With `interactions=2` each (persona, task, seed) runs twice in the same scene: the second interaction's
student prompt carries the prior-knowledge summary of the first (`prior.prior_summary`: what the user
answered). The teacher is the scripted oracle or an LLM (`relabel.LLMTeacher`). `build` runs the units on
worker processes (`harness.workers.run_stream_pool`), the parent writing every row.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field, replace

from ..errors import AdaptError
from ..harness.batches import episode_id
from ..harness.episode import Episode
from ..harness.policy import Decision
from ..harness.rollout import Job
from ..harness.workers import run_stream_pool, stop_signals
from ..llm.backend import Request
from ..llm.chat import render
from ..llm.policies import sample_key
from ..llm.prompts import ACTION_PREFIX
from ..runtime.env import MAX_STEPS, make_env
from .dataset import PairStore, mix_line, row_key
from .decide import EPS1, EPS2, decide
from .equivalent import equivalent
from .ids import rejected_turn_ids
from .prior import prior_summary
from .relabel import (
    Proposal,
    ScriptedTeacher,
    answered_prompt,
    preference_question,
    proposals,
    question_text,
    reflection_request,
    topic_question,
    topics,
)
from .rows import completion_tokens, fit_prompt
from .score import SCORE_DTYPE, Step, steps_probabilities

PHASES = ("student", "teacher", "reflection", "scoring")
MAX_LENGTH = 8192  # fits the shipped students' prompts at 50 steps (docs/training.md): no row is shrunk


class TooLong(AdaptError, ValueError):
    """A row whose task, questions and answers alone exceed `max_length`: a usage error (raise it)."""

    exit_code = 2


@dataclass(frozen=True)
class DataSettings:
    """What `adapt train data` builds: the split, the selection, the thresholds and limits."""

    split: str | None
    personas: tuple
    tasks: tuple
    seeds: tuple = (100,)  # training scenes: never the evaluation seeds 0-3 (harness.seeds)
    interactions: int = 1
    questions: str = "student"  # or "topics", "choices"
    eps1: float = EPS1
    eps2: float = EPS2
    max_length: int | None = MAX_LENGTH
    width: int = 8
    workers: int = 1
    max_steps: int = MAX_STEPS  # step budget per episode (the paper's 50)
    skip_after_failures: int | None = None  # skip steps after N failures in a row (ours, off by default)
    skip_equivalent: bool = False  # skip steps whose a^s ends as well as a^t under the oracle (ours, `equivalent`)
    follow_questions: bool = False  # the rollout asks a^q where the rule chose it, never one asked before (ours)


@dataclass
class Timings:
    """Seconds spent per phase and steps considered (the benchmark's split)."""

    seconds: dict = field(default_factory=lambda: dict.fromkeys(PHASES, 0.0))

    def add(self, phase: str, t0: float) -> None:
        """Add the time since `t0` to `phase`."""
        self.seconds[phase] += time.perf_counter() - t0


@dataclass
class _Run:
    job: Job
    interaction: int
    episode: Episode
    prior: str = ""
    failures: int = 0
    made_after: list = field(default_factory=list)
    proposal: Proposal | None = None  # the teacher's at the step being considered (a^t, preferences, reason)
    follow: str | None = None  # with `follow_questions`: the chosen question this step takes instead of a^s


def units(settings: DataSettings) -> list:
    """(persona, task, seed) in order: each runs its interactions one after the other."""
    return [(p, t, s) for p in settings.personas for t in settings.tasks for s in settings.seeds]


def jobs(settings: DataSettings) -> list:
    """(persona, task, seed, interaction) in order."""
    return [(*u, i) for u in units(settings) for i in range(1, settings.interactions + 1)]


def same_action(parser, student: str, teacher: str) -> bool:
    """Whether student and teacher act the same: the same parsed action, verb and every slot (`Look for
    animal products` and `Look for skillet` are both `look_for`, and differ), or the same text."""
    if student.strip() == teacher.strip():
        return True
    ps, pt = parser.parse(student), parser.parse(teacher)
    return ps is not None and ps == pt  # Parsed is frozen: its action and its slots


class Builder:
    """Builds the pairs of a selection with one student and one teacher."""

    def __init__(self, domain, student, settings: DataSettings, store: PairStore, model_name: str, teacher=None):
        self.domain, self.student, self.s, self.store = domain, student, settings, store
        self.teacher = teacher if teacher is not None else ScriptedTeacher(domain)
        self.model_name = model_name
        self.topics = topics(domain)
        self.times = Timings()
        self.parser = student.index.parser

    def run(self, progress=None) -> None:
        """Every unit, `width` at a time (each unit's interactions in turn); `progress(episodes done,
        episodes)`."""
        todo = units(self.s)
        n = self.s.interactions
        for i in range(0, len(todo), self.s.width):
            self.run_units(todo[i:i + self.s.width])
            if progress is not None:
                progress(n * min(i + self.s.width, len(todo)), n * len(todo))

    def run_units(self, batch: list) -> None:
        """Interaction 1 of every (persona, task, seed) of `batch` stepped together, then interaction 2
        with the summary of each one's first as its prior knowledge, and so on."""
        priors: dict = {}
        for i in range(1, self.s.interactions + 1):
            runs = [self._start(*u, i, priors.get(u, "")) for u in batch]
            self._episodes(runs)
            for u, r in zip(batch, runs, strict=True):
                priors[u] = prior_summary(r.episode)

    def _start(self, persona, task, seed, interaction, prior: str = "") -> _Run:
        job = Job(self.student.name, persona, task, seed)
        env = make_env(self.domain, persona, task, seed, max_steps=self.s.max_steps)
        ep = Episode(f"{episode_id(job)}/i{interaction}", env)
        self.student.start(ep.id, env)
        self.student.priors[ep.id] = prior
        t0 = time.perf_counter()
        self.teacher.start(ep.id, env)  # the oracle searches its plan here: teacher time
        self.times.add("teacher", t0)
        return _Run(job, interaction, ep, prior)

    def _episodes(self, runs: list) -> None:
        while True:
            live = [r for r in runs if not r.episode.done]
            if not live:
                break
            self._step(live)
        for r in runs:
            self.student.end(r.episode.id)
            self.teacher.end(r.episode.id)

    def _step(self, live: list) -> None:
        views = [r.episode.view() for r in live]
        t0 = time.perf_counter()
        decisions = self.student.act_batch(views)
        self.times.add("student", t0)
        todo = []
        for r, v, d in zip(live, views, decisions, strict=True):
            key = (r.job.persona, r.job.task, r.job.seed, r.interaction, v.step)
            if not self.store.done(key):
                todo.append((r, v, d))
            elif self.s.follow_questions:  # a resumed step: the question its row chose, as the first run took it
                r.follow = self.store.chosen_question(key)
        self._consider(todo)
        for r, d in zip(live, decisions, strict=True):
            turn = r.episode.apply(self._taken(r, d))
            r.failures = 0 if turn.ok else r.failures + 1
            r.made_after.append(tuple(r.episode.view().made))

    def _taken(self, r: _Run, decision):
        """What the rollout does at this step: the student's decision, or with `follow_questions` the
        question the decision rule chose in its place (the user's reply then stays in the history, so the
        steps after it are the student's with that answer known; the row keeps a^s as rejected)."""
        q, r.follow = r.follow, None
        if q is None or self._answered(r, q):  # a row of an older build may have chosen a question asked before
            return decision
        return Decision(q, decision.prompt, None, {"followed": "question"})

    def _consider(self, todo: list) -> None:
        t0 = time.perf_counter()
        props = proposals(self.teacher, [v for _, v, _ in todo])
        self.times.add("teacher", t0)
        asks = []
        for (r, v, d), prop in zip(todo, props, strict=True):
            r.proposal, a_t = prop, prop.action
            reason = self._skip(r, d.action, a_t)
            if reason:
                self.store.append(self._row(r, v, d, a_t, None, reason))
            else:
                asks.append((r, v, d, a_t))
        questions = self._reflect(asks)
        self._asked([(r, v, d, a_t, q) for (r, v, d, a_t), q in zip(asks, questions, strict=True)])

    def _asked(self, items: list) -> None:
        """The rows of the steps that asked: each fitted and its question answered in turn, then all
        scored in one batch (`steps_probabilities`) and written in order. On `TooLong` the rows before
        the one that does not fit are still scored and written."""
        ready = []
        try:
            for r, v, d, a_t, q in items:
                ready.append(self._ready(r, v, d, a_t, q))
        except TooLong:
            self._score_rows(items, ready)
            raise
        self._score_rows(items, ready)

    def _ready(self, r: _Run, view, decision, a_t: str, q: str):
        """(fitted prompt, the user's answer, the `Step` to score) of an asked step."""
        tok = self.student.backend.tokenizer
        fitted = self._fit(r, view, decision.prompt, decision.action, a_t, q)
        answer = r.episode.env.user(question_text(q) or q, ()) if question_text(q) else ""
        x = render(tok, fitted.prompt)  # exactly the prompt the row trains on
        xq = render(tok, answered_prompt(self.student, fitted.prompt, view, q, answer))
        ids = (decision.stats or {}).get("token_ids")
        return fitted, answer, Step(x, xq, a_t, decision.action, None if ids is None else tuple(ids))

    def _score_rows(self, items: list, ready: list) -> None:
        t0 = time.perf_counter()
        probs = steps_probabilities(self.student.backend, [step for _, _, step in ready], SCORE_DTYPE)
        self.times.add("scoring", t0)
        for (r, v, d, a_t, q), (fitted, answer, _), p in zip(items, ready, probs, strict=False):
            row = self._row(r, v, d, a_t, q, None, fitted, answer, p)
            self.store.append(row)
            if self.s.follow_questions and row["kind"] == "question":
                r.follow = q

    def _skip(self, r: _Run, student: str, teacher: str) -> str | None:
        n = self.s.skip_after_failures
        if n and r.failures >= n:
            return f"after_{n}_failures"
        if same_action(self.parser, student, teacher):
            return "same_action"
        if self.s.skip_equivalent and self._equivalent(r, student, teacher):
            return "equivalent"
        return None

    def _equivalent(self, r: _Run, student: str, teacher: str) -> bool:
        """With `skip_equivalent` and the scripted teacher: whether a^s (not a question) ends the episode as
        well as a^t in no more steps, each followed by the teacher's plan (`equivalent`; teacher time)."""
        policy = getattr(self.teacher, "policy", None)
        if policy is None or not hasattr(policy, "next_step") or question_text(student) is not None:
            return False
        t0 = time.perf_counter()
        try:
            return equivalent(r.episode, student, teacher, policy)
        finally:
            self.times.add("teacher", t0)

    def _reflect(self, asks: list) -> list:
        t0 = time.perf_counter()
        if self.s.questions in ("topics", "choices"):
            out = [self._topic_question(r, v, a_t) for r, v, _, a_t in asks]
        else:
            reqs = [replace(reflection_request(self.student, v, d.action, a_t, tuple(r.made_after), r.proposal.reason),
                            key=sample_key(v, "reflection")) for r, v, d, a_t in asks]  # the episode's own stream
            out = [c.text.strip() for c in self.student.backend.generate(reqs)] if reqs else []
        self.times.add("reflection", t0)
        return out

    def _topic_question(self, r: _Run, view, a_t: str) -> str:
        """The topic proposer: with `choices`, the question of the choice a^t realises (`oracle-ask`'s words);
        else (or without one) a question about the first preference the teacher named, else the topic
        sharing most words with a^t."""
        if self.s.questions == "choices" and r.proposal.questions:
            return f'Ask "{r.proposal.questions[0]}"'
        named = r.proposal.preferences
        if named:
            persona = r.episode.env.persona
            return preference_question(next(p for p in persona.preferences if p.id == named[0]))
        return topic_question(self.topics, a_t, view.task_text)

    def _row(self, r: _Run, view, decision, a_t: str, q: str | None, reason: str | None, fitted=None,
             answer: str | None = None, probs=None) -> dict:
        """A step's row: skipped for `reason`, or (reason None) an asked step with its fitted prompt, the
        user's answer and its scores (`_asked`), the decision rule picking the chosen completion."""
        tok = self.student.backend.tokenizer
        if fitted is None:
            fitted = self._fit(r, view, decision.prompt, decision.action, a_t, q)
        prompt = fitted.prompt
        kind = "skipped"
        if reason is None:
            eps1 = float("inf") if self._answered(r, q) else self.s.eps1
            d = decide(probs.p_teacher, probs.p_teacher_given_answer, probs.p_student, eps1, self.s.eps2)
            kind, reason = d.kind, d.skip_reason
        chosen = {"question": q, "teacher": a_t}.get(kind)
        ids, canon = rejected_turn_ids(tok, prompt, decision.action, decision.stats)
        row = self._fields(r, view, decision.action, a_t, q, answer, probs, kind, reason, chosen, prompt,
                           fitted.tokens, fitted.truncated)
        row.update(qa_kept=fitted.qa_kept, qa_total=fitted.qa_total, over_budget=False, max_steps=self.s.max_steps,
                   rejected_token_ids=ids, rejected_canonical=canon,
                   score_dtype=self.student.backend.score_dtype(SCORE_DTYPE) if probs else None)
        return row

    def _answered(self, r: _Run, q: str | None) -> bool:
        """With `follow_questions`: whether the episode already asked `q` (its answer is in the prompt, so
        asking again can tell the student nothing: the rule goes on as if Δq were below ε1)."""
        return self.s.follow_questions and q is not None and any(t.action == q for t in r.episode.history)

    def _fit(self, r: _Run, view, prompt, a_s: str, a_t: str, q: str | None):
        """The row's prompt fitted to `max_length` with room for the longest completion it may take (the
        student's action, the teacher's, the question): every question and answer kept; `TooLong` when
        they alone do not fit."""
        tok = self.student.backend.tokenizer
        room = completion_tokens(tok, *(ACTION_PREFIX + t for t in (a_s, a_t, q) if t))
        fitted = fit_prompt(tok, prompt, room, self.s.max_length)
        if fitted.over:
            need = fitted.tokens + room
            raise TooLong(f"--max-length {self.s.max_length} cannot hold the task and the {fitted.qa_total} "
                          f"question(s) and answer(s) of {r.job.persona}/{r.job.task} seed {r.job.seed} step "
                          f"{view.step} ({need} tokens with every other observation left out): raise "
                          f"--max-length to at least {need}")
        return fitted

    def _fields(self, r, view, a_s, a_t, q, answer, probs, kind, reason, chosen, prompt, n, cut) -> dict:
        msg = lambda t: [{"role": "assistant", "content": ACTION_PREFIX + t}]  # noqa: E731
        p = probs
        return {
            "prompt": [dict(m) for m in prompt.messages], "chosen": msg(chosen) if chosen else None,
            "rejected": msg(a_s), "kind": kind, "skip_reason": reason, "teacher_action": a_t,
            "student_action": a_s, "question": q, "answer": answer,
            "question_source": self.s.questions if q else None,
            "p_teacher": p and p.p_teacher, "p_teacher_given_answer": p and p.p_teacher_given_answer,
            "p_student": p and p.p_student,
            "delta_q": p and p.p_teacher_given_answer - p.p_teacher, "delta_t": p and p.p_student - p.p_teacher,
            "eps1": self.s.eps1, "eps2": self.s.eps2, "prompt_tokens": n, "truncated": cut,
            "spec_hash": self.domain.spec_hash, "split": self.s.split, "persona": r.job.persona,
            "task": r.job.task, "seed": r.job.seed, "interaction": r.interaction, "step": view.step,
            "prior": r.prior, "student_model": self.model_name, "teacher": self.teacher.name,
            "teacher_model": self.teacher.model, "teacher_preferences": list(r.proposal.preferences),
            "teacher_reason": r.proposal.reason}


def opening_tokens(domain, student, settings: DataSettings) -> int:
    """Tokens of the shortest row the first unit can make: its opening prompt (instructions, layout, task)
    and a short completion; `--max-length` below it cannot hold any row."""
    persona, task, seed = units(settings)[0]
    env = make_env(domain, persona, task, seed, max_steps=settings.max_steps)
    view = Episode("opening", env).view()
    tok = student.backend.tokenizer
    return len(tok(render(tok, student.builder.prompt(view)), add_special_tokens=False)["input_ids"]) + 32


class Sink:
    """A worker's stand-in for the `PairStore`: the parent's keys (already written) and the rows made
    since the last `take`."""

    def __init__(self, keys, questions=None):
        self.keys, self.rows, self.questions = set(keys), [], dict(questions or {})

    def done(self, key: tuple) -> bool:
        """Whether the parent's file already has this step."""
        return tuple(key) in self.keys

    def chosen_question(self, key: tuple) -> str | None:
        """The question the parent's row of this step chose, if it chose one."""
        return self.questions.get(tuple(key))

    def append(self, row: dict) -> None:
        """Keep a row for the parent."""
        self.rows.append(row)

    def take(self) -> list:
        """The rows kept so far, forgotten here."""
        out, self.rows = self.rows, []
        return out


def _chunks(it, n: int):
    chunk = []
    for x in it:
        chunk.append(x)
        if len(chunk) == n:
            yield chunk
            chunk = []
    if chunk:
        yield chunk


def _work(make_builder, store, width: int):
    """A worker's loop: `width` units at a time, one record per unit (its rows; the chunk's phase seconds
    ride on the first)."""
    keys, questions = store.keys, store.questions

    def work(jobs):
        sink = Sink(keys, questions)
        b = make_builder(sink)
        for chunk in _chunks(jobs, width):
            before = dict(b.times.seconds)
            try:
                b.run_units(chunk)
            except TooLong as exc:  # the parent raises it: one line, not a dead worker
                yield None, [], {"error": str(exc)}
                return
            spent = {k: b.times.seconds[k] - before[k] for k in PHASES}
            rows: dict = {u: [] for u in chunk}
            for row in sink.take():
                rows[(row["persona"], row["task"], row["seed"])].append(row)
            for j, u in enumerate(chunk):
                yield u, rows[u], spent if j == 0 else dict.fromkeys(PHASES, 0.0)
    return work


def build(make_builder, settings: DataSettings, store: PairStore, progress=None) -> Timings:
    """Build every unit's rows into `store`: in this process (rows written as they are made) or, with
    `settings.workers` > 1, on forked worker processes pulling units from one queue (each unit's rows
    written when it finishes; a kill loses at most the units in flight, resumed on the next run).
    `make_builder(store)` makes a `Builder` writing to `store`. Returns the seconds per phase (summed
    over workers)."""
    todo = units(settings)
    if settings.workers <= 1 or len(todo) <= 1:
        b = make_builder(store)
        with stop_signals():  # Ctrl-C / SIGTERM: `Interrupted`, every row written so far kept
            b.run(progress)
        return b.times
    times, n = Timings(), settings.interactions
    width = min(settings.width, -(-len(todo) // settings.workers))  # no worker hoards the units another could run
    records = run_stream_pool(todo, settings.workers, _work(make_builder, store, width))
    for done, (u, rows, spent) in enumerate(records, 1):
        if u is None:
            raise TooLong(spent["error"])
        for row in rows:
            if not store.done(row_key(row)):
                store.append(row)
        for k, v in spent.items():
            times.seconds[k] += v
        if progress is not None:
            progress(n * done, n * len(todo))
    return times


def mix(rows: list) -> Counter:
    """Counts by kind."""
    return Counter(r["kind"] for r in rows)


__all__ = ["MAX_LENGTH", "Builder", "DataSettings", "Request", "Sink", "TooLong", "build", "opening_tokens", "jobs", "mix", "mix_line", "row_key", "units"]
