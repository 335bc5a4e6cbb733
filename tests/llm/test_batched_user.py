"""Batched user answers: `Env.pending_question` predicts exactly what a step asks, the harness groups the
questions of a round (`prepare_answers`), and the LLM user's batched answers equal its one-at-a-time
answers on the tiny model."""

from __future__ import annotations

import shutil

import pytest

from adaptbench.harness.episode import iter_batch, prepare_answers
from adaptbench.harness.policy import Policy
from adaptbench.runtime.env import Env

# Asks that succeed, fail their precondition (the repeat limit), do not parse, and plain actions.
SCRIPT = ('Ask "How do you like your eggs?"', "Look for eggs", 'Ask "Milk?"', "Open fridge_0",
          'Ask "Milk?"', 'Ask "Milk?"', "Ask milk please", "Move egg_0 to counter_0", 'Ask "Which pan?"',
          "Declare Done")
EPISODES = (("juan", "eggs", 0), ("miranda", "eggs", 1), ("juan", "toast_coffee", 2), ("miranda", "tea_eggs", 0))


class Script(Policy):
    """The same actions in every episode, one per step."""

    name = "script"

    def __init__(self, steps=SCRIPT):
        self.steps = steps

    def act(self, view):
        """The next scripted action."""
        return self.steps[len(view.history)]


class Recorder:
    """A user that records each call."""

    def __init__(self):
        self.calls = []

    def answer(self, question, dialogue=()):
        """A reply naming the question."""
        self.calls.append((question, dialogue))
        return f"about {question}"


class Batching(Recorder):
    """A user that answers in batches: prepared answers are marked, grouped by `key`."""

    batches: list = []

    def __init__(self, key=0):
        super().__init__()
        self.key, self.ready = key, {}

    def batch_key(self):
        """Users with the same key answer together."""
        return self.key

    @staticmethod
    def prepare_answers(asks):
        """Record the group; keep an answer per user."""
        Batching.batches.append([(id(u), q) for u, q, _ in asks])
        for user, question, dialogue in asks:
            user.ready = {(question, dialogue): f"prepared {question}"}

    def answer(self, question, dialogue=()):
        """The prepared answer for exactly this question and dialogue, else a fresh one."""
        self.calls.append((question, dialogue))
        return self.ready.pop((question, dialogue), f"fresh {question}")


def test_pending_question_is_what_the_step_asks_and_changes_nothing(domain):
    rec = Recorder()
    env = Env(domain, "eggs", "juan", 0, user=rec)
    assert env.answerer is rec
    for action in SCRIPT:
        before = (env.world.step, len(env.world.trace), env.world.questions, len(rec.calls))
        pending = env.pending_question(action)
        assert (env.world.step, len(env.world.trace), env.world.questions, len(rec.calls)) == before
        env.step(action)
        asked = rec.calls[before[3]:]
        assert asked == ([pending] if pending is not None else []), action
    assert env.done and env.pending_question('Ask "More?"') is None
    assert Env(domain, "eggs", "juan", 0).pending_question('Ask "Eggs?"') is None  # no user


def test_harness_groups_questions_by_key_and_leaves_other_users_alone(domain):
    Batching.batches.clear()
    users = [Batching(0), Batching(1), Batching(0), Recorder()]
    envs = [(f"e{i}", Env(domain, "eggs", "juan", i, user=u)) for i, u in enumerate(users)]
    eps = {ep.id: ep for ep in iter_batch(Script(), envs)}
    asks_ok = [s for s, t in zip(SCRIPT, eps["e0"].steps, strict=False) if s.startswith("Ask") and t.ok]
    assert len(asks_ok) == 4  # the third 'Ask "Milk?"' hits the repeat limit; 'Ask milk please' does not parse
    assert len(Batching.batches) == 2 * len(asks_ok)  # one call per key per round that asks
    assert sorted(len(b) for b in Batching.batches) == [1] * len(asks_ok) + [2] * len(asks_ok)
    for i, u in enumerate(users):
        replies = [t.reply for t in eps[f"e{i}"].steps if t.reply]
        prefix = "prepared" if isinstance(u, Batching) else "about"
        assert len(replies) == len(asks_ok) and all(r.startswith(prefix) for r in replies), replies
        assert not getattr(u, "ready", {})  # every prepared answer was used
    # a prepared answer for another question is not used
    env = Env(domain, "eggs", "juan", 0, user=Batching())
    prepare_answers([(env, 'Ask "Eggs?"')])
    assert env.step('Ask "Milk?"').reply == 'fresh "Milk?"'


def _rollout(domain, backend, width, sessions=True):
    from adaptbench.llm.user import LLMUser

    users = [LLMUser(backend, domain, domain.persona[p], domain.task[t], max_tokens=12) for p, t, _ in EPISODES]
    for user in users:
        user.session = user.session if sessions else None
    envs = []
    for (p, t, seed), user in zip(EPISODES, users, strict=True):
        env = Env(domain, t, p, seed, user=user)
        user.bind(env)
        envs.append((f"{p}/{t}/{seed}", env))
    eps = {ep.id: ep for ep in iter_batch(Script(), envs, width=width)}
    return [[s.reply for s in eps[eid].steps] for eid, _ in envs], users


class Counting:
    """A backend wrapper that counts generate calls and their rows."""

    def __init__(self, backend):
        self.backend, self.tokenizer, self.calls, self.cached = backend, backend.tokenizer, [], []

    def generate(self, requests):
        """The wrapped backend's completions."""
        self.calls.append(len(requests))
        outs = self.backend.generate(requests)
        self.cached += [o.stats.get("cached_tokens", 0) for o in outs]
        return outs

    def config(self):
        """The wrapped backend's configuration."""
        return self.backend.config()


@pytest.fixture(scope="module")
def sharp(tiny, tmp_path_factory):
    """The tiny model with its matrices redrawn at std 0.5: the random tiny model answers every prompt
    alike (its small weights barely attend to the context); this one's greedy answers depend on the prompt,
    so equal answers mean equal computations."""
    import torch
    from transformers import AutoModelForCausalLM

    from adaptbench.llm.hf import TransformersBackend

    out = tmp_path_factory.mktemp("sharp") / "model"
    shutil.copytree(tiny, out)
    model = AutoModelForCausalLM.from_pretrained(out)
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in model.parameters():
            if p.dim() == 2:
                p.normal_(0, 0.5, generator=gen)
    model.save_pretrained(out)
    return TransformersBackend(str(out), batch_size=16)


def test_llm_user_batched_answers_equal_one_at_a_time(domain, sharp):
    batched, single = Counting(sharp), Counting(sharp)
    together, users = _rollout(domain, batched, width=len(EPISODES))
    alone, _ = _rollout(domain, single, width=1)
    fresh, _ = _rollout(domain, sharp, width=1, sessions=False)  # every prompt read whole, no cache kept
    assert together == alone == fresh
    assert len({r for rows in together for r in rows if r}) > len(EPISODES)  # answers depend on the prompt
    asks = sum(1 for r in together[0] if r)
    assert asks == 4 and all(sum(1 for r in rows if r) == asks for rows in together)
    assert batched.calls == [len(EPISODES)] * asks  # one generate per round that asks, every episode in it
    assert sum(batched.cached[len(EPISODES):]) > 0  # later answers read the opening from the user's cache
    assert single.calls == [1] * (asks * len(EPISODES))
    assert all(len(u.calls) == asks and all(c[3] == len(EPISODES) for c in u.calls) for u in users)


class Failing(Batching):
    """A batching user whose batched call raises."""

    @staticmethod
    def prepare_answers(asks):
        """Fail."""
        raise RuntimeError("server down")


def test_a_failing_batch_falls_back_to_answers_in_the_step_when_catching(domain):
    envs = [(f"e{i}", Env(domain, "eggs", "juan", i, user=Failing())) for i in range(2)]
    eps = list(iter_batch(Script(), envs, catch=True))
    assert all(ep.error is None and ep.steps[0].reply == 'fresh "How do you like your eggs?"' for ep in eps)
    envs = [(f"e{i}", Env(domain, "eggs", "juan", i, user=Failing())) for i in range(2)]
    with pytest.raises(RuntimeError, match="server down"):
        list(iter_batch(Script(), envs))


def test_llm_user_uses_a_prepared_answer_only_for_the_same_prompt(domain, backend):
    from adaptbench.llm.user import LLMUser

    counting = Counting(backend)
    user = LLMUser(counting, domain, domain.persona["juan"], domain.task["eggs"], max_tokens=4)
    env = Env(domain, "eggs", "juan", 0, user=user)
    user.bind(env)
    prepare_answers([(env, 'Ask "Eggs?"')])
    env.step("Look for eggs")  # the state the user reads changed: the prepared answer no longer applies
    env.step('Ask "Eggs?"')
    assert counting.calls == [1, 1] and user._prepared == {}
    prepare_answers([(env, 'Ask "Milk?"')])
    env.step('Ask "Milk?"')
    assert counting.calls == [1, 1, 1] and [c[3] for c in user.calls] == [1, 1]
