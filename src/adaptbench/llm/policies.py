"""Language-model policies (`harness.policy.Policy`): planner, teacher, ReAct, never-ask and always-ask,
each a prompt kind plus a grammar variant, batched over episodes through one backend.

    policy = LLMPolicy(backend, domain, "planner")
    decisions = policy.act_batch(views)        # one batched generation for every view

Per episode the policy keeps the state's grammar (`grammars.StateGrammar`, updated incrementally from
the view's `observed`) and the progress line after each step. The teacher also keeps the episode's
env (`start`) to read the persona's preferences and, each step, those the verifier finds unmet.
ReAct generates a one-line thought unconstrained (stopped at the newline), then the action under the
grammar. Always-ask switches to the Ask-only grammar when none of the last N actions was a question.
"""

from __future__ import annotations

import time

from ..grammars import QUESTION_SETS, GrammarCache
from ..harness.policy import Decision, Policy
from ..runtime.index import runtime_index
from . import boundary
from .backend import ModelError, Request, context_limit
from .chat import fit, render
from .prompts import ACTION_PREFIX, ASK_EVERY, PromptBuilder

AGENTS = {"planner": "planner", "teacher": "teacher", "react": "react", "never-ask-llm": "never_ask",
          "always-ask-llm": "always_ask"}  # agent name -> prompt kind
VARIANTS = {"never_ask": "never_ask"}  # prompt kind -> grammar variant (default otherwise)
THOUGHT_TOKENS = 48


def sample_key(view, call: str) -> str:
    """The random stream of one generation (`Request.key`, `llm.sampling`): the episode id (agent, persona,
    task, scene seed), the step and the call (`thought`, `action`): an episode's samples do not depend on
    the batch, the worker or the order it ran in."""
    return f"{view.episode}/{view.step}/{call}"


class _Episode:
    """What the policy remembers of one episode."""

    def __init__(self, grammar):
        self.grammar = grammar
        self.made_after: list = []
        self.env = None


class LLMPolicy(Policy):
    """A language-model agent of one kind (`AGENTS`) over a backend."""

    def __init__(self, backend, domain, agent: str = "planner", level: str = "observed", budget: int | None = None,
                 max_tokens: int = 48, every: int = ASK_EVERY, user: str = "the user", questions: str = "free"):
        if agent not in AGENTS:
            raise ValueError(f"unknown LLM agent '{agent}' (choose from: {', '.join(AGENTS)})")
        if questions not in QUESTION_SETS:
            raise ValueError(f"unknown question set '{questions}' (choose from: {', '.join(QUESTION_SETS)})")
        self.questions = questions  # `bank`: an Ask names one of the domain's questions (grammars.emit)
        self.name, self.kind = agent, AGENTS[agent]
        self.backend, self.domain, self.level = backend, domain, level
        self.max_tokens, self.every = max_tokens, every
        self.builder = PromptBuilder(domain, self.kind, user=user, every=every)
        self.index = runtime_index(domain)
        self.grammars = GrammarCache(self.index.grammar, {t.id: t.text for t in domain.tasks})
        self.context = getattr(backend, "context", None) or context_limit(backend.tokenizer)
        self.budget = budget if budget is not None else self._default_budget()
        if self.context and self.budget is not None and self.budget + self._reserved() > self.context:
            raise ModelError(f"--budget {self.budget} plus {self._reserved()} generated tokens exceeds the model's "
                             f"context ({self.context} tokens): use --budget {max(self.context - self._reserved(), 0)} "
                             "or less (prompts are cut to the budget), or a model with a longer context")
        self._episodes: dict = {}
        self.priors: dict = {}  # episode id -> what is known about the user beforehand (the prompt's prior line)

    def _reserved(self) -> int:
        """Tokens a step may generate after its prompt (ReAct: a thought, then the action)."""
        return self.max_tokens + THOUGHT_TOKENS

    def _default_budget(self) -> int | None:
        """The model's context less what a step generates (None: no context known, prompts uncut); a
        context that leaves no room for a prompt is a ModelError."""
        if not self.context:
            return None
        if self.context <= self._reserved():
            raise ModelError(f"the model's context ({self.context} tokens) leaves no room for a prompt after "
                             f"{self._reserved()} generated tokens; use a model with a longer context")
        return self.context - self._reserved()

    def config(self) -> dict:
        """Agent, prompt kind, grammar level (and question set, when not free), token limits and the
        backend's model."""
        return {"agent": self.name, "prompt": self.kind, "level": self.level, "budget": self.budget,
                **({"questions": self.questions} if self.questions != "free" else {}),
                "max_tokens": self.max_tokens, **({"every": self.every} if self.kind == "always_ask" else {}),
                **self.backend.config()}

    def start(self, episode: str, env) -> None:
        """Forget any earlier episode of this id; the teacher keeps the env to read verdicts."""
        self._episodes.pop(episode, None)
        if self.kind == "teacher":
            self._state(episode, None).env = env

    def end(self, episode: str) -> None:
        """Forget the episode (and the backend's cache of it)."""
        self._episodes.pop(episode, None)
        self.priors.pop(episode, None)
        self.backend.release(episode)

    def _state(self, episode: str, view) -> _Episode:
        ep = self._episodes.get(episode)
        if ep is None:
            ep = self._episodes[episode] = _Episode(None)
        if ep.grammar is None and view is not None:
            ep.grammar = self.grammars.state(view.task, view.observed, self.level,
                                             VARIANTS.get(self.kind, "default"), self.questions)
        return ep

    def force_ask(self, view) -> bool:
        """Always-ask: whether none of the last N actions (N taken) was a question."""
        if self.kind != "always_ask" or len(view.history) < self.every:
            return False
        return not any(t.action.startswith("Ask ") for t in view.history[-self.every:])

    def _knowledge(self, ep: _Episode) -> tuple:
        if ep.env is None or ep.env.persona is None:
            return (), ()
        prefs = tuple(p.text for p in ep.env.persona.preferences)
        unmet = tuple(v.text for v in ep.env.evaluate().verdicts if v.verdict == "violated")
        return prefs, unmet

    def _prepare(self, view) -> tuple:
        ep = self._state(view.episode, view)
        del ep.made_after[max(len(view.history) - 1, 0):]
        if view.history:
            ep.made_after.append(tuple(view.made))
        force = self.force_ask(view)
        prefs, unmet = self._knowledge(ep)
        kw = {"preferences": prefs, "unmet": unmet, "force_ask": force, "made_after": tuple(ep.made_after),
              "prior": self.priors.get(view.episode, "")}
        prompt = fit(self.backend.tokenizer, lambda omit: self.builder.prompt(view, omit=omit, **kw), self.budget)
        self._check_fits(prompt)
        text = ep.grammar.update(view.observed)
        if force:
            text = self.grammars.state(view.task, view.observed, self.level, "ask_only", self.questions).text
        return prompt, text, force

    def _check_fits(self, prompt) -> None:
        """ModelError when even the shortest prompt (every older step left out) and what a step generates
        do not fit the model's context: the model cannot play this benchmark."""
        over = prompt.meta.get("over_budget", 0)
        if over and self.context and self.budget + over + self._reserved() > self.context:
            raise ModelError(f"the shortest prompt ({self.budget + over} tokens: instructions, layout, task and "
                             f"the last step) and {self._reserved()} generated tokens do not fit the model's "
                             f"context ({self.context} tokens); use a model with a longer context")

    def act(self, view) -> Decision:
        """The next action for one episode."""
        return self.act_batch([view])[0]

    def act_batch(self, views) -> list:
        """The next action for every view: one batched generation (two for ReAct: thoughts, then
        actions)."""
        t0 = time.perf_counter()
        prepared = [self._prepare(v) for v in views]
        texts = [render(self.backend.tokenizer, p) for p, _, _ in prepared]
        prep_seconds = time.perf_counter() - t0
        thoughts = [""] * len(views)
        if self.kind == "react":
            todo = [i for i, (_, _, force) in enumerate(prepared) if not force]
            outs = boundary.generate(self.backend, [Request(texts[i], None, ("\n",), THOUGHT_TOKENS, session=views[i].episode,
                                                    key=sample_key(views[i], "thought")) for i in todo])
            for i, out in zip(todo, outs, strict=True):
                thoughts[i] = out.text.strip()
                texts[i] += thoughts[i] + "\n" + ACTION_PREFIX
        outs = boundary.generate(self.backend, [Request(t, g, (), self.max_tokens, self._parses, v.episode,
                                                sample_key(v, "action"))
                                      for t, (_, g, _), v in zip(texts, prepared, views, strict=True)])
        return [self._decision(p, out, force, thought, prep_seconds / len(views))
                for (p, _, force), out, thought in zip(prepared, outs, thoughts, strict=True)]

    def _parses(self, text: str) -> bool:
        """Whether the simulator's parser reads an action text (validates a served model's output)."""
        return self.index.parser.parse(text) is not None

    def _decision(self, prompt, out, force: bool, thought: str, prep: float) -> Decision:
        parsed = self.index.parser.parse(out.text)
        stats = {"prompt_tokens": out.prompt_tokens, "omitted": prompt.omitted, "tokens": out.tokens,
                 "level": self.level, "grammar": "ask_only" if force else VARIANTS.get(self.kind, "default"),
                 "accepted": out.accepted, "parsed": parsed.action if parsed else None,
                 "prepare_seconds": round(prep, 4), **out.stats}
        if thought:
            stats["thought"] = thought
        if out.token_ids is not None:  # what the model generated (after the healed prompt: stats["healed"])
            stats["token_ids"] = list(out.token_ids)
        over = prompt.meta.get("over_budget", 0)
        if over:  # the shortest prompt (every older step left out) still exceeds the budget
            stats["over_budget"], stats["over_budget_tokens"] = True, over
        return Decision(out.text, None, out.text, stats)
