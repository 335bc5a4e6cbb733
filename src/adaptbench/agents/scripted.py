"""Scripted agents that plan from the recipes in the spec, as `harness.policy.Policy` classes.

- `oracle`: the privileged teacher. At `start` it reads the persona's preferences and searches the
  recipe choices in private simulations of the episode (greedy coordinate search) for the plan the
  verifiers accept best.
- `never-ask`: the same planner with the recipes' sensible defaults and no questions.
- `always-ask`: asks the user at every choice point that has a question (as its action; the reply
  comes back in the view's history) and follows the answers.
- `oracle-ask`: the oracle's plan, with the question of every choice point where that plan departs from
  the defaults (what an agent without the persona could not have known) asked first: the planning
  choices' at the start, a recipe's just before the recipe. The teacher-with-questions of the student's
  pretraining data.

All of them explore like a real agent: they `Look for` things before using them, and they read only
what they have found (`View.seen`). Each emits one action per `act`; `harness.episode` runs the loop.
"""

from __future__ import annotations

import re
from abc import abstractmethod
from collections import Counter

from ..compiler import ast as A
from ..compiler.lint import applies_to
from ..compiler.model import Choice, CompiledDomain, Persona, Task
from ..harness.policy import Decision, Policy, View
from ..runtime.env import Env
from ..runtime.users import words
from .plan_cache import searched
from .plans import (
    PLAN,
    Executor,
    Feedback,
    all_recipes,
    choice_points,
    defaults,
    execute,
    feedback,
    task_recipes,
)

AGENTS = ("oracle", "never-ask", "always-ask", "oracle-ask")


class ScriptedPolicy(Policy):
    """A planner driven one action at a time: `plan(view)` returns a generator that yields action
    texts and is sent a `plans.Feedback` after each (one generator per running episode)."""

    def __init__(self, domain: CompiledDomain):
        self.domain = domain
        self._runs: dict = {}

    @abstractmethod
    def plan(self, view: View):
        """The action generator of a new episode."""

    def act(self, view: View) -> Decision:
        """The plan's next action (Declare Done once the plan is exhausted)."""
        run = self._runs.get(view.episode)
        try:
            if run is None or not view.history:
                run = self._runs[view.episode] = self.plan(view)
                return Decision(next(run))
            return Decision(run.send(feedback(view)))
        except StopIteration:
            self._runs.pop(view.episode, None)
            return Decision("Declare Done")

    def end(self, episode: str) -> None:
        """Forget a finished episode's plan."""
        self._runs.pop(episode, None)

    def notes(self, task: str) -> tuple:
        """What the scripted agents cannot do on `task` (`no recipe for component X`), kept in each record."""
        from .plans import notes

        return tuple(notes(self.domain, self.domain.task[task]))


# ------------------------------------------------------------------ never-ask
class NeverAsk(ScriptedPolicy):
    """Defaults everywhere, no questions."""

    name = "never-ask"

    def plan(self, view: View):
        """Carry out the recipes' defaults."""
        task = self.domain.task[view.task]
        return Executor(self.domain, task, defaults(self.domain, all_recipes(self.domain, task)), view.seen).steps()


# ------------------------------------------------------------------ always-ask
_NEGATORS = {"no", "not", "without", "avoid", "never", "instead", "free", "skip", "nothing", "neither", "nor"}
# where a negation's scope ends: its context ("in my coffee", "on sweet breakfasts"), an exception ("other
# than salt", "except butter", "but", "unless"), or the next clause ("and", "so", "then", "plus")
_SCOPE_ENDS = {"in", "on", "to", "with", "for", "at", "into", "onto", "when", "while", "if", "but", "except",
               "other", "than", "unless", "and", "so", "then", "plus", "please"}
_SCOPE = 6  # words at most


def option_words(domain: CompiledDomain, value: str) -> tuple[set, set]:
    """(specific words, general words) describing an option."""
    specific = set(words(value.replace("_", " ")))
    general: set = set()
    if value in domain.substance:
        s = domain.substance[value]
        specific |= words(s.description) | words(s.category.replace("_", " "))
        general |= {w for t in s.tags for w in words(t.replace("_", " "))}
    elif value in domain.entity:
        e = domain.entity[value]
        specific |= words(e.description) | words(e.category.replace("_", " "))
        general |= {w for t in e.tags for w in words(t.replace("_", " "))}
    return specific, general


def _negated(answer: str) -> set:
    """Content words inside a negation's scope: from a negator ("no", "without", "not", "don't" ...) to the
    end of its list, i.e. up to a clause break (sentence punctuation), a word that starts the negation's
    context or an exception ("on my toast", "in my coffee", "other than", "except", "but", "and"), at most
    six words: "No toppings like fruit or nuts on my sweet breakfasts" negates toppings, fruit and nuts."""
    toks = re.findall(r"[a-z]+|[.;!?]", re.sub(r"\b(do|does)n't\b", r"\1 not", answer.lower()))
    out = set()
    for i, t in enumerate(toks):
        if t not in _NEGATORS:
            continue
        scope = []
        for w in toks[i + 1: i + 1 + _SCOPE]:
            if w in _SCOPE_ENDS or not w.isalpha():
                break
            scope.append(w)
        out |= words(" ".join(scope))
    return out


def _ruled_out(value: str, spec: set, gen: set, said: set, negated: set) -> bool:
    """Whether an answer rules an option out. A negated class of it ("no toppings like fruit") rules it out
    unless the answer names it outside the negation ("no fruit except kiwi"); a negated word of its own
    ("no plant-based milks") unless another of its own words is said outside it ("dairy milk")."""
    free = said - negated
    if gen & negated and not words(value.replace("_", " ")) & free:
        return True
    return bool(spec & negated) and not spec & free


def interpret(domain: CompiledDomain, choice: Choice, answer: str):
    """The option(s) an answer asks for; the default when it names none."""
    said, negated = words(answer), _negated(answer)
    scores = {}
    for v in choice.values:
        spec, gen = option_words(domain, v)
        if _ruled_out(v, spec, gen, said, negated):
            scores[v] = -1.0
            continue
        scores[v] = 2.0 * len(spec & said) + 1.0 * len(gen & said)
    if choice.multi:
        picked = tuple(v for v in choice.values if scores[v] >= 2.0)
        return picked
    best = max(choice.values, key=lambda v: (scores[v], -choice.values.index(v)))
    if scores[best] > 0:
        return best
    if "none" in choice.values and min(scores.values()) < 0:  # the answer ruled an option out: none of them
        return "none"
    return choice.default[0]


class AlwaysAsk(ScriptedPolicy):
    """Ask at every choice point (planning choices first, then each recipe's), then act on the answers."""

    name = "always-ask"

    def plan(self, view: View):
        """Questions first, then the plan the answers choose."""
        return self._steps(self.domain.task[view.task], view.seen)

    def _steps(self, task: Task, seen):
        d = self.domain
        assignment: dict = {}
        for c in d.planning:
            if c.ask:
                fb = yield f'Ask "{c.ask}"'
                seen, assignment[f"{PLAN}.{c.id}"] = fb.seen, interpret(d, c, fb.reply)
        for r in task_recipes(d, task, assignment):
            for c in r.choices:
                if c.ask:
                    fb = yield f'Ask "{c.ask}"'
                    seen, assignment[f"{r.id}.{c.id}"] = fb.seen, interpret(d, c, fb.reply)
        plan = {**defaults(d, all_recipes(d, task)), **assignment}
        yield from Executor(d, task, plan, seen).steps()


# ------------------------------------------------------------------ oracle
def rule_names(domain: CompiledDomain, persona: Persona, task: Task) -> set:
    """Every name the persona's preferences about this task mention."""
    out = set()
    for pref in persona.preferences:
        if applies_to(domain, pref, task):
            out |= {n.name for n in A.walk(pref.rule) if isinstance(n, A.ClsName)}
    for name in list(out):
        style = domain.style.get(name)
        if style is not None:
            out |= set(style.words) | set(style.verbs)
            if style.rule is not None:
                out |= {n.name for n in A.walk(style.rule) if isinstance(n, A.ClsName)}
            for alt in style.process:  # the classes a process is about (`food: ice` for iced)
                out |= {v.strip() for k, val in alt if k in ("food", "with") for v in str(val).split("|")}
    return out


def _info(domain: CompiledDomain, value: str) -> set:
    if value in domain.substance:
        s = domain.substance[value]
        return {value, s.category, *s.tags}
    if value in domain.entity:
        e = domain.entity[value]
        room = e.location
        while room in domain.entity and domain.entity[room].location is not None:
            room = domain.entity[room].location
        return {value, e.category, *e.tags, room or ""}
    members = [e for e in domain.entities if e.category == value] + [s for s in domain.substances if s.category == value]
    return {value} | {t for m in members for t in m.tags}


def _relevant(domain: CompiledDomain, choice: Choice, value: str, names: set) -> bool:
    catalogue = value in domain.entity or value in domain.substance or any(c == value for c, _ in domain.categories)
    needs = next((o.needs for o in choice.options if o.value == value), ())
    if not catalogue and not needs:
        return True
    return bool(set().union(_info(domain, value), *(_info(domain, n) for n in needs)) & names)


def candidate(domain: CompiledDomain, choice: Choice, current, value: str, names: set):
    """The assignment value that tries `value` for a choice point, or None if not worth trying."""
    if choice.multi:
        if value in current:
            return tuple(x for x in current if x != value)
        if _relevant(domain, choice, value, names):
            return tuple(x for x in choice.values if x in current or x == value)
        return None
    if value != current and (_relevant(domain, choice, value, names) or _relevant(domain, choice, current, names)):
        return value
    return None


class Oracle:
    """Greedy search over recipe choices, scored by the persona's verifiers in the simulator."""

    def __init__(self, domain: CompiledDomain, task: Task, persona: Persona, seed, full_scene: bool,
                 rounds: int = 3):
        self.domain, self.task, self.persona = domain, task, persona
        self.seed, self.full, self.rounds = seed, full_scene, rounds
        self.simulations = 0
        self._scores: dict = {}

    def evaluation(self, assignment: dict):
        """The verdicts of a plan, simulated (one evaluation per distinct trace of actions)."""
        env = Env(self.domain, task=self.task.id, persona=self.persona, seed=self.seed, full_scene=self.full)
        env.reset()
        execute(env, assignment)
        self.simulations += 1
        trace = tuple(e.text for e in env.world.trace)
        if trace not in self._scores:  # different choices often end in the same actions
            self._scores[trace] = env.evaluate()
        return self._scores[trace]

    def score(self, assignment: dict) -> float:
        """satisfied - 2 x violated (+ half the progress of violated ones) of a plan, simulated."""
        ev = self.evaluation(assignment)
        near = sum(v.progress for v in ev.verdicts if v.verdict == "violated")
        # a violation costs more than a satisfied preference gains: adding honey to satisfy a sweet-only
        # rule must not pay for breaking "butter only on toast" (toast with honey is sweet)
        return ev.satisfied - 2 * ev.violated + 0.5 * near

    def reasons(self, plan: dict) -> dict:
        """(choice key, value) -> the ids of the preferences that made `plan` choose that value over the
        default: those whose verdict is worse in the plan without it (a single choice back at its default,
        a multi choice without that item). Only the values the plan departs from the defaults with; a
        value that serves no preference maps to ()."""
        base = _standing(self.evaluation(plan))
        out = {}
        for key, choice in choice_points(self.domain, all_recipes(self.domain, self.task)):
            if key not in plan or not self._active(key, choice, plan):
                continue
            if choice.multi:
                alts = {v: tuple(x for x in plan[key] if x != v) for v in plan[key] if v not in choice.default}
            else:
                alts = {plan[key]: choice.default[0]} if plan[key] != choice.default[0] else {}
            for v, alt in alts.items():
                out[(key, v)] = _worse(base, _standing(self.evaluation({**plan, key: alt})))
        return out

    def search(self) -> dict:
        """The best assignment found."""
        recipes = all_recipes(self.domain, self.task)
        # toppings and other additions before substitutions: adding to a default dish first keeps
        # the search out of corners (granola as the cereal itself cannot come after the fruit)
        points = sorted(choice_points(self.domain, recipes), key=lambda p: (p[0].split(".")[0] != PLAN,
                                                                           not p[1].multi))
        names = rule_names(self.domain, self.persona, self.task)
        best_a = defaults(self.domain, recipes)
        best = self.score(best_a)
        unchanged = 0  # choice points checked since the last improvement
        self.use_swaps = False  # swaps are tried once single changes have converged
        for step in range((self.rounds + 1) * len(points)):
            key, choice = points[step % len(points)]
            improved = False
            if not self._active(key, choice, best_a):
                unchanged += 1
                continue
            tried: set = set()
            while True:  # candidates are rebuilt from the best so far after each improvement
                fresh = [c for c in self._candidates(choice, best_a, key, names) if c not in tried]
                better = None
                for cand in fresh:
                    tried.add(cand)
                    s = self.score({**best_a, key: cand})
                    if s > best + 1e-9:
                        better, best = cand, s
                        break
                if better is None:
                    break
                best_a, improved = {**best_a, key: better}, True
            if improved and self.use_swaps:  # a swap helped: back to single changes
                self.use_swaps, unchanged = False, 0
                continue
            unchanged = 0 if improved else unchanged + 1
            if unchanged >= len(points):  # a full cycle without improvement: converged
                if self.use_swaps:
                    break
                self.use_swaps, unchanged = True, 0
        return best_a


    def _active(self, key: str, choice: Choice, assignment: dict) -> bool:
        """Whether a choice point can matter under the current plan (its recipe is in it)."""
        rid = key.split(".", 1)[0]
        if rid == PLAN:
            return True
        recipe = self.domain.recipe[rid]
        if recipe not in task_recipes(self.domain, self.task, assignment):
            return False
        if recipe.optional and not choice.multi:
            return any(assignment.get(f"{rid}.{c.id}") for c in recipe.choices if c.multi)
        return True

    def _candidates(self, choice: Choice, best_a: dict, key: str, names: set):
        """Single changes; once those have converged, swaps of a chosen item for another of its family."""
        if self.use_swaps:
            if choice.multi:
                yield from swaps(self.domain, choice, best_a[key], names)
            return
        for value in choice.values:
            cand = candidate(self.domain, choice, best_a[key], value, names)
            if cand is not None:
                yield cand


_RANK = {"violated": 0, "inapplicable": 1, "satisfied": 2}


def _standing(ev) -> dict:
    """Preference id -> (verdict rank, progress): how well an evaluation treats each preference."""
    return {v.id: (_RANK[v.verdict], v.progress if v.verdict == "violated" else 0.0) for v in ev.verdicts}


def _worse(base: dict, other: dict) -> tuple:
    """The ids (in the persona's order) that `other` treats worse than `base`."""
    return tuple(pid for pid, s in base.items() if other.get(pid, s) < s)


def _category(domain: CompiledDomain, value: str) -> str:
    """The family an option is swapped within: the first of the engine's `swap_families` (cereal, fruit,
    sweetener ...) it has, or its category."""
    item = domain.substance.get(value) or domain.entity.get(value)
    if item is None:
        members = [e for e in domain.entities if e.category == value]
        item = members[0] if members else None
    if item is None:
        return value
    families = domain.engine.swap_families
    return next((f for f in families if f in item.tags or f == item.category), item.category)


_LAYERS = frozenset(("breakfast_cereal", "fruit", "nut", "seed"))  # what layers a parfait: one can stand in for another


def _swappable(domain: CompiledDomain, old: str, new: str) -> bool:
    a, b = _category(domain, old), _category(domain, new)
    return a == b or (a in _LAYERS and b in _LAYERS)


def swaps(domain: CompiledDomain, choice: Choice, current: tuple, names: set):
    """Multi-choice values with one chosen item replaced by a relevant item of the same family (fruit, nuts,
    seeds and cereal stand in for each other: muesli for the last banana of a no-fruit parfait)."""
    for old in current:
        for new in choice.values:
            if new not in current and _swappable(domain, old, new) and _relevant(domain, choice, new, names):
                yield tuple(new if x == old else x for x in current)


class OraclePolicy(ScriptedPolicy):
    """The privileged teacher: at `start` it searches the best plan for the persona in private
    simulations of the episode's scene, then carries it out (no questions)."""

    name = "oracle"

    def __init__(self, domain: CompiledDomain):
        super().__init__(domain)
        self._plans: dict = {}
        self._oracles: dict = {}
        self._reasons: dict = {}

    def start(self, episode: str, env) -> None:
        """Search the plan (privileged: reads the persona and simulates the scene)."""
        self._runs.pop(episode, None)
        self._reasons.pop(episode, None)
        oracle = self._oracles[episode] = Oracle(env.domain, env.task, env.persona, env.scene.seed, env.scene.full)
        self._plans[episode] = searched(oracle)  # or the plan the same search found before (`plan_cache`)

    def executor(self, view: View) -> Executor:
        """An executor of the plan found at `start`, from the view's known world."""
        return Executor(self.domain, self.domain.task[view.task], self._plans[view.episode], view.seen)

    def plan(self, view: View):
        """Carry out the plan found at `start`."""
        return self.executor(view).steps()

    def next_step(self, view: View) -> tuple:
        """(the plan's next action from the view's state, the (choice key, value) pairs it realises).

        The action: the plan re-executed from the view's known world, passing over each action the
        agent has already taken with success (the same action up to instance numbers and a move's
        source, `step_effect`): what is left of the plan in the state the agent reached."""
        ex = self.executor(view)
        done = Counter(step_effect(t.action) for t in view.history if t.ok)
        steps, fb = ex.steps(), Feedback(True, "", view.seen)
        try:
            action = next(steps)
            while action != "Declare Done" and done[step_effect(action)] > 0:
                done[step_effect(action)] -= 1
                action = steps.send(fb)
        except StopIteration:
            return "Declare Done", ()
        return action, ex.serves

    def proposal(self, view: View) -> tuple:
        """(the plan's next action from the view's state, the ids of the preferences it serves): those that
        decided the choices the action realises (`Oracle.reasons`); () for an action that realises no
        departure from the defaults (a plain cooking step, a default choice)."""
        action, serves = self.next_step(view)
        return action, self.preferences(view.episode, serves)

    def questions(self, episode: str, serves) -> tuple:
        """The questions (each choice point's `ask`, as `oracle-ask` asks them) of the (choice key, value)
        pairs `serves` that some preference decided: what the student could have asked to know the choice
        the action realises; () when it serves no preference."""
        reasons = self._plan_reasons(episode)
        points = dict(choice_points(self.domain, all_recipes(self.domain, self._oracles[episode].task)))
        return tuple(dict.fromkeys(points[k].ask for k, v in serves
                                   if reasons.get((k, v)) and k in points and points[k].ask))

    def preferences(self, episode: str, serves) -> tuple:
        """The ids of the preferences behind (choice key, value) pairs of an episode's plan, in order."""
        reasons = self._plan_reasons(episode)
        return tuple(dict.fromkeys(pid for kv in serves for pid in reasons.get(kv, ())))

    def _plan_reasons(self, episode: str) -> dict:
        """`Oracle.reasons` of the episode's plan, computed on first use (rollouts never pay for it)."""
        if episode not in self._reasons:
            self._reasons[episode] = self._oracles[episode].reasons(self._plans[episode])
        return self._reasons[episode]

    def end(self, episode: str) -> None:
        """Forget a finished episode's plan."""
        super().end(episode)
        for d in (self._plans, self._oracles, self._reasons):
            d.pop(episode, None)


_SOURCE = re.compile(r"^(Move|Pour) (\S+) from \S+ (to|into) ")


_INSTANCE = re.compile(r"_\d+\b")


def step_effect(action: str) -> str:
    """What an action does, for matching a plan's steps against the agent's: its text with instance
    numbers dropped (`egg_0` and `egg_2` are both an egg) and without the source of a `Move X from Y to
    Z` / `Pour X from Y into Z` (where an item came from does not change what the step did)."""
    return _INSTANCE.sub("", _SOURCE.sub(r"\1 \2 \3 ", action.strip()))


class OracleAskPolicy(OraclePolicy):
    """The oracle's plan, asking first where it departs from the defaults: before acting on a choice it
    could only know from the persona, it asks that choice's question (each question once per episode),
    then carries the plan out as the oracle does (the answers do not change the plan)."""

    name = "oracle-ask"

    def plan(self, view: View):
        """The questions of the choices the plan changes, each before the recipe that uses it."""
        return self._steps(self.domain.task[view.task], self._plans[view.episode], view.seen)

    def _steps(self, task: Task, assignment: dict, seen):
        d = self.domain
        ex, asked = Executor(d, task, assignment, seen), set()
        recipes = task_recipes(d, task, assignment)
        yield from self._ask(ex, departures(d, assignment, [(f"{PLAN}.{c.id}", c) for c in d.planning]), asked)
        for recipe in recipes:
            points = [(f"{recipe.id}.{c.id}", c) for c in recipe.choices]
            if not recipe.optional or any(assignment.get(k) for k, c in points if c.multi):
                yield from self._ask(ex, departures(d, assignment, points), asked)
            yield from ex.run_recipe(recipe)
        yield from ex.act("Declare Done")

    @staticmethod
    def _ask(ex: Executor, questions, asked: set):
        for q in questions:
            if q not in asked:
                asked.add(q)
                yield from ex.act(f'Ask "{q}"')


def departures(domain: CompiledDomain, assignment: dict, points) -> list:
    """The questions of the choice points (key, Choice) whose value in `assignment` is not the default."""
    out = []
    for key, c in points:
        default = c.default if c.multi else c.default[0]
        if c.ask and key in assignment and assignment[key] != default:
            out.append(c.ask)
    return out


POLICIES = {"oracle": OraclePolicy, "never-ask": NeverAsk, "always-ask": AlwaysAsk, "oracle-ask": OracleAskPolicy}


def make_policy(agent: str, domain: CompiledDomain) -> ScriptedPolicy:
    """The scripted policy named `agent` (one of AGENTS) for a domain."""
    return POLICIES[agent](domain)


def play(agent: str, env: Env, episode: str = "episode"):
    """Run one whole episode of a scripted agent on `env` (reset first) with the harness's loop;
    returns the `harness.episode.Episode` (its steps; `env` holds the final world)."""
    from ..harness.episode import run_episode

    return run_episode(make_policy(agent, env.domain), env, episode)
