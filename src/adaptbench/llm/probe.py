"""The answer-use probe: pairs of planner prompts that differ only in the user's answer to one question,
and whether a model's next action follows the answer (`adapt probe answers`, docs/llm.md).

    pairs = build_pairs(domain, tasks=["eggs"], seeds=[0])
    result = probe(backend_scorer(backend), pairs)     # result.share, result.baseline

A pair comes from one persona's preference and one choice point of a task's recipes (egg style, bread,
milk, pour order ...): the question is the choice's question (the one the scripted askers ask), which the
persona's offline user answers from that preference (`OfflineUser.pick`, the matcher `adapt users check`
probes); answer A is the preference's answer, answer B another persona's preference answered to the same
question that asks for a different option. What an answer asks for is the always-ask agent's reading of
it (`agents.scripted.interpret`). Two plans, the recipes' defaults with that one choice set to each answer's
option, are carried out in the same scene, the question asked where the oracle-ask agent asks it (just
before the recipe; `at="start"`: as the first action) and answered A or B. The probe state is the first
step where the two plans' actions differ: the histories up to it are the same but for the answer.

"Follows" is scored, no generation: under answer A, the model's log-probability of A's action beats that of
B's action (and the reverse under B; a tie follows neither). A model that ignores the answer sees two
identical prompts and prefers the same action in both, so it follows in exactly one of the two: 50% of
prompts, 0% of pairs.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from ..agents.plans import PLAN, Executor, all_recipes, choice_points, defaults, feedback, task_recipes
from ..agents.scripted import interpret, option_words
from ..compiler.lint import applies_to
from ..harness.episode import Episode
from ..harness.policy import Decision
from ..runtime.env import Env
from ..runtime.users import OfflineUser, first_person, words
from .prompts import Prompt, PromptBuilder

PLACES = ("recipe", "start")
IGNORING_SHARE = 0.5  # the share of prompts a model that ignores answers follows (exactly one of each pair)
IGNORING_PAIRS = 0.0  # the share of pairs it follows under both answers
# What following an answer takes, by how the pair's two actions differ: "named", they name different things
# (`Look for almond_milk` / `Look for milk`: the answer's own words lead to the action); "object", they differ
# only in which instance of a thing they use (`Move pan_1 to stove_0` / `Move pan_0 to stove_0`: the model must
# find in an earlier observation which instance the answer describes, `pan_1 (cast iron pan)`)
KINDS = ("named", "object")
_INSTANCE = re.compile(r"_\d+\b")


@dataclass(frozen=True)
class Side:
    """One answer of a pair: whose preference it is, its text, the option it asks for, the action its
    plan takes at the probe state, and the planner prompt at that state."""

    persona: str
    preference: str
    answer: str
    option: object
    action: str
    prompt: Prompt


@dataclass(frozen=True)
class Pair:
    """Two prompts that differ only in the user's answer to `question` (choice point `choice` of `task`,
    scene `seed`), at history length `step`."""

    task: str
    choice: str
    question: str
    seed: int
    step: int
    a: Side
    b: Side

    @property
    def kind(self) -> str:
        """"object" when the two actions differ only in instance numbers, else "named" (`KINDS`)."""
        return "object" if _INSTANCE.sub("", self.a.action) == _INSTANCE.sub("", self.b.action) else "named"

    def key(self) -> str:
        """What names the pair in reports: task/choice/persona.preference vs persona.preference/seed."""
        return (f"{self.task}/{self.choice}/{self.a.persona}.{self.a.preference}"
                f" vs {self.b.persona}.{self.b.preference}/{self.seed}")


# ------------------------------------------------------------------ what an answer asks for
def asked_for(domain, choice, answer: str):
    """The option(s) of `choice` an answer asks for (the always-ask agent's reading), or None when the
    answer names none of its options by their own words (only by a tag such as `savory`: it is not about
    this choice)."""
    answer = readable(answer)
    said = words(answer)
    if not any(option_words(domain, v)[0] & said for v in choice.values):
        return None
    return interpret(domain, choice, answer)


_PARTICIPLE = re.compile(r"\b[a-z]{3,}ed\b", re.I)
_FREE = re.compile(r"\b([a-z]+)-free\b", re.I)


def readable(answer: str) -> str:
    """The answer as the always-ask reading should take it: each past participle followed by the verbs it
    may come from (options named by their verb, `scramble`, `poach`, `fry`, are read from `scrambled`,
    `poached`, `fried`), and `X-free Y` said as `Y ... free of X` (the reading negates the words after
    `free`: lactose-free cheese is cheese, not no cheese)."""
    def stems(m: re.Match) -> str:
        word = m.group(0)
        if word.endswith("ied"):
            return f"{word} {word[:-3]}y"
        return f"{word} {word[:-1]} {word[:-2]}"
    frees = _FREE.findall(answer)
    answer = _FREE.sub("", answer) + "".join(f" Free of {x}." for x in frees)
    return _PARTICIPLE.sub(stems, answer)


def answer_of(pref) -> str:
    """What the offline user says for a preference: its `answer`, or its text in the first person."""
    return pref.answer or first_person(pref.text)


def _about(domain, persona, task, question: str) -> list:
    """The persona's preferences that apply to the task and that the offline user answers `question` from."""
    return [p for p in OfflineUser(domain, persona, task).pick(question) if applies_to(domain, p, task)]


def _contrasts(domain, task, choice, question: str, option, skip: str):
    """(persona, preference, answer, option) of other personas whose answer to `question` asks for an
    option other than `option`, in the spec's order."""
    for persona in domain.personas:
        if persona.id == skip:
            continue
        for pref in _about(domain, persona, task, question):
            other = asked_for(domain, choice, answer_of(pref))
            if other is not None and other != option:
                yield persona, pref, answer_of(pref), other


# ------------------------------------------------------------------ the two episodes
def _steps(domain, task, assignment: dict, seen, question: str, key: str, at: str):
    """The plan's actions with the question asked at the start or just before its choice's recipe."""
    ex = Executor(domain, task, assignment, seen)
    rid = key.split(".", 1)[0]
    ask = f'Ask "{question}"'
    if at == "start" or rid == PLAN:
        yield from ex.act(ask)
    for recipe in task_recipes(domain, task, assignment):
        if at == "recipe" and recipe.id == rid:
            yield from ex.act(ask)
        yield from ex.run_recipe(recipe)
    yield from ex.act("Declare Done")


def trace(domain, task, persona, seed: int, assignment: dict, question: str, key: str, answer: str,
          at: str = "recipe", max_steps: int = 50) -> list:
    """Carry out a plan in the scene of `seed` with a user who answers `answer`: one (view, progress lines
    after each earlier step, action) per step, in order."""
    env = Env(domain, task.id, persona, seed, user=lambda q, dialogue: answer, max_steps=max_steps)
    ep = Episode("probe", env)
    view, made_after, out = ep.view(), [], []
    steps = _steps(domain, task, assignment, view.seen, question, key, at)
    try:
        text = next(steps)
        while True:
            out.append((view, tuple(made_after), text))
            ep.apply(Decision(text))
            view = ep.view()
            made_after.append(tuple(view.made))
            if ep.done:
                break
            text = steps.send(feedback(view))
    except StopIteration:
        pass
    return out


def _diverge(a: list, b: list):
    """The first index at which two traces take different actions (None if they never do)."""
    return next((i for i, (x, y) in enumerate(zip(a, b, strict=False)) if x[2] != y[2]), None)


# ------------------------------------------------------------------ pairs
@dataclass(frozen=True)
class _Probe:
    """One preference's question about one choice point, before a contrast and a scene are chosen."""

    persona: object
    pref: object
    task: object
    key: str
    choice: object
    question: str
    option: object


def _probes(domain, tasks, personas):
    """Every (persona, preference, task, choice point) whose question the preference answers and whose
    answer asks for one of the choice's options."""
    for task in tasks:
        points = [(k, c) for k, c in choice_points(domain, all_recipes(domain, task)) if c.ask]
        for persona in personas:
            for key, choice in points:
                for pref in _about(domain, persona, task, choice.ask):
                    option = asked_for(domain, choice, answer_of(pref))
                    if option is not None:
                        yield _Probe(persona, pref, task, key, choice, choice.ask, option)


def _pair(domain, pr: _Probe, seed: int, at: str, max_steps: int, builder: PromptBuilder):
    """The pair of a probe in one scene: with the first contrasting answer whose plan acts differently
    within the step limit (None if none does)."""
    base = defaults(domain, all_recipes(domain, pr.task))
    answer = answer_of(pr.pref)
    a = trace(domain, pr.task, pr.persona, seed, {**base, pr.key: pr.option}, pr.question, pr.key, answer,
              at, max_steps)
    tried = set()
    for persona, pref, other, option in _contrasts(domain, pr.task, pr.choice, pr.question, pr.option,
                                                   pr.persona.id):
        if (other, option) in tried or other == answer:
            continue
        tried.add((other, option))
        b = trace(domain, pr.task, pr.persona, seed, {**base, pr.key: option}, pr.question, pr.key, other,
                  at, max_steps)
        i = _diverge(a, b)
        if i is None:
            continue
        return Pair(pr.task.id, pr.key, pr.question, seed, i,
                    _side(builder, pr.persona.id, pr.pref.id, answer, pr.option, a[i]),
                    _side(builder, persona.id, pref.id, other, option, b[i]))
    return None


def _side(builder: PromptBuilder, persona: str, pref: str, answer: str, option, step) -> Side:
    view, made_after, action = step
    return Side(persona, pref, answer, option, action, builder.prompt(view, made_after=made_after))


def build_pairs(domain, tasks=None, personas=None, seeds=(0,), at: str = "recipe", max_steps: int = 50) -> list:
    """Every probe pair of the given tasks and personas (ids; None: all) in the scenes of `seeds`: one per
    (persona, preference, task, choice point, seed) that has a contrasting answer whose plan acts
    differently. `at`: where the question is asked ("recipe": just before its choice's recipe, as the
    oracle-ask agent asks; "start": as the first action)."""
    if at not in PLACES:
        raise ValueError(f"unknown place '{at}' (choose from: {', '.join(PLACES)})")
    tasks = [domain.task[t] for t in tasks] if tasks else list(domain.tasks)
    personas = [domain.persona[p] for p in personas] if personas else list(domain.personas)
    builder = PromptBuilder(domain, "planner")
    out = []
    for pr in _probes(domain, tasks, personas):
        for seed in seeds:
            pair = _pair(domain, pr, seed, at, max_steps, builder)
            if pair is not None:
                out.append(pair)
    return out


# ------------------------------------------------------------------ templated answers (training data)
SAYINGS = ("I'd like {}.", "{}, please.", "I prefer {}.", "Please use {}.")  # one per scene seed, in turn


def option_phrases(domain, value: str) -> list:
    """Ways to name an option in a reply, plainest first: its id's words (not an instance's: `table 0`), its
    description, its category."""
    spec = domain.substance.get(value) or domain.entity.get(value)
    out = [] if re.search(r"_\d+$", value) else [value.replace("_", " ")]
    if spec is not None:
        out += [spec.description, spec.category.replace("_", " ")]
    return list(dict.fromkeys(p for p in out if p))


def said_answer(domain, choice, value: str, saying: str) -> str | None:
    """A templated reply asking for exactly `value` (the always-ask reading of it gives that option and
    no other), or None when no phrase of the option reads back to it alone."""
    want = (value,) if choice.multi else value
    for phrase in option_phrases(domain, value):
        answer = saying.format(phrase)
        answer = answer[0].upper() + answer[1:]
        if asked_for(domain, choice, answer) == want:
            return answer
    return None


def said_pairs(domain, tasks=None, seeds=(100,), at: str = "recipe", persona=None, max_steps: int = 50) -> list:
    """Pairs like `build_pairs`', with templated replies in place of personas' preferences: for every asked
    choice point of each task and every option of it but "none", a reply naming that option (`said_answer`,
    the saying chosen by the scene seed) against the next option (in the choice's order, wrapping round)
    whose plan acts differently. They cover every option, where personas' answers cover those some persona
    prefers, and use no persona's words (`persona`, default the first, only hosts the episode). Sides are
    labelled persona "said"."""
    if at not in PLACES:
        raise ValueError(f"unknown place '{at}' (choose from: {', '.join(PLACES)})")
    tasks = [domain.task[t] for t in tasks] if tasks else list(domain.tasks)
    host = domain.persona[persona] if persona else domain.personas[0]
    builder = PromptBuilder(domain, "planner")
    out = []
    for seed in seeds:
        saying = SAYINGS[seed % len(SAYINGS)]
        for task in tasks:
            base = defaults(domain, all_recipes(domain, task))
            for key, choice in choice_points(domain, all_recipes(domain, task)):
                if not choice.ask:
                    continue
                said = {v: said_answer(domain, choice, v, saying) for v in choice.values if v != "none"}
                said = {v: a for v, a in said.items() if a}
                for v in said:
                    pair = _said_pair(domain, task, host, key, choice, base, said, v, seed, at, max_steps, builder)
                    if pair is not None:
                        out.append(pair)
    return out


def _said_pair(domain, task, host, key, choice, base, said, value, seed, at, max_steps, builder):
    """The pair of one option's templated reply against the next option whose plan acts differently (None if
    none does within the step limit)."""
    def plan(v):
        return {**base, key: (v,) if choice.multi else v}
    a = trace(domain, task, host, seed, plan(value), choice.ask, key, said[value], at, max_steps)
    options = list(said)
    k = options.index(value)
    for other in options[k + 1:] + options[:k]:  # the next options first: contrasts spread over them all
        answer = said[other]
        b = trace(domain, task, host, seed, plan(other), choice.ask, key, answer, at, max_steps)
        step = _diverge(a, b)
        if step is not None:
            return Pair(task.id, key, choice.ask, seed, step,
                        _side(builder, "said", value, said[value], value, a[step]),
                        _side(builder, "said", other, answer, other, b[step]))
    return None


def spread(pairs: list, limit: int | None) -> list:
    """At most `limit` pairs taken evenly across the list (every task, choice and persona keeps its share);
    all of them when `limit` is None or 0."""
    if not limit or len(pairs) <= limit:
        return list(pairs)
    return [pairs[i * len(pairs) // limit] for i in range(limit)]


# ------------------------------------------------------------------ scoring
Scorer = Callable[[Prompt, tuple], tuple]  # (prompt, (action_a, action_b)) -> (score_a, score_b)


@dataclass(frozen=True)
class PairScore:
    """A model's scores of the two actions under each answer: `under_a` = (A's action, B's action) after
    answer A, `under_b` the same after answer B."""

    pair: Pair
    under_a: tuple
    under_b: tuple

    @property
    def follows_a(self) -> bool:
        """Under answer A the model prefers A's action."""
        return self.under_a[0] > self.under_a[1]

    @property
    def follows_b(self) -> bool:
        """Under answer B the model prefers B's action."""
        return self.under_b[1] > self.under_b[0]

    @property
    def shift(self) -> float:
        """How much the answer moves the model towards its action: the margin of A's action over B's under
        A less the same margin under B (0 for a model that ignores the answer)."""
        return (self.under_a[0] - self.under_a[1]) - (self.under_b[0] - self.under_b[1])


@dataclass(frozen=True)
class ProbeResult:
    """The shares of a model over a set of pairs, beside what a model that ignores answers gets."""

    pairs: int
    prompts_followed: int
    pairs_followed: int
    mean_shift: float
    scores: tuple = ()

    @property
    def share(self) -> float:
        """The share of prompts whose preferred action is their answer's (ignoring answers: 50%)."""
        return self.prompts_followed / (2 * self.pairs) if self.pairs else 0.0

    @property
    def share_se(self) -> float:
        """The standard error of `share`, over pairs (each pair's share of its two prompts)."""
        n = len(self.scores)
        if n < 2:
            return 0.0
        xs = [(s.follows_a + s.follows_b) / 2 for s in self.scores]
        mean = sum(xs) / n
        return (sum((x - mean) ** 2 for x in xs) / (n - 1) / n) ** 0.5

    @property
    def pair_share(self) -> float:
        """The share of pairs that follow both answers (ignoring answers: 0%)."""
        return self.pairs_followed / self.pairs if self.pairs else 0.0

    def by_kind(self) -> dict:
        """The result over each kind of pair that occurs (`Pair.kind`), in `KINDS` order."""
        return {k: result_of([s for s in self.scores if s.pair.kind == k])
                for k in KINDS if any(s.pair.kind == k for s in self.scores)}

    def summary(self, kinds: bool = True) -> dict:
        """The figures as JSON-ready values; with `kinds`, the same figures by kind of pair under "by_kind"."""
        out = {"pairs": self.pairs, "share": self.share, "share_se": self.share_se, "ignoring_share": IGNORING_SHARE,
               "pair_share": self.pair_share, "ignoring_pair_share": IGNORING_PAIRS,
               "prompts_followed": self.prompts_followed, "pairs_followed": self.pairs_followed,
               "mean_shift": self.mean_shift}
        if kinds and self.scores:
            out["by_kind"] = {k: r.summary(kinds=False) for k, r in self.by_kind().items()}
        return out


def result_of(scores) -> ProbeResult:
    """The shares over a list of `PairScore`s."""
    n = len(scores)
    return ProbeResult(n, sum(s.follows_a + s.follows_b for s in scores), sum(s.follows_a and s.follows_b for s in scores),
                       sum(s.shift for s in scores) / n if n else 0.0, tuple(scores))


def probe(scorer: Scorer, pairs, progress=None) -> ProbeResult:
    """Score both actions under both answers of every pair; `progress(done, total)` after each pair."""
    scores = []
    for i, pair in enumerate(pairs):
        actions = (pair.a.action, pair.b.action)
        scores.append(PairScore(pair, tuple(scorer(pair.a.prompt, actions)), tuple(scorer(pair.b.prompt, actions))))
        if progress is not None:
            progress(i + 1, len(pairs))
    return result_of(scores)


def backend_scorer(backend) -> Scorer:
    """A scorer over a backend: each action's summed log-probability (its tokens and the end token) after the
    rendered prompt. ModelError when a prompt and an action do not fit the model's context."""
    from .backend import ModelError, continuation_ids
    from .chat import count, render

    seen: dict = {}  # one prompt is often the contrast of several pairs

    def score(prompt: Prompt, actions: tuple) -> tuple:
        text = render(backend.tokenizer, prompt)
        if (text, actions) in seen:
            return seen[text, actions]
        context = getattr(backend, "context", None)
        need = count(backend.tokenizer, text) + max(len(continuation_ids(backend.tokenizer, a)) for a in actions)
        if context and need > context:
            raise ModelError(f"a probe prompt and its action take {need} tokens, more than the model's context "
                             f"({context}); use --at recipe (shorter histories) or a model with a longer context")
        out = seen[text, actions] = tuple(sum(s.logprobs) for s in backend.score(text, list(actions)))
        return out
    return score
