"""Reflection that knows why (issue 27 item 5): rows record the preferences the teacher's action serves and
its thought; the reflection prompt carries the thought in the paper's words; `--questions topics` asks about
the preference the teacher named (the word-overlap topic when it named none)."""

from __future__ import annotations

from adaptbench.training.dataset import PairStore
from adaptbench.training.relabel import Proposal

from .conftest import SKIP_MODELS, play

REASON = "Since Ron prefers this: \"Add lactose-free cheese to eggs\", my next step is Look for cheese."


class NamingTeacher:
    """A teacher that proposes `Look for cheese` for ron's lactose-free cheese at every step but the first
    (which serves no preference)."""

    name, model = "oracle", None

    def start(self, episode, env):
        """Nothing to plan."""

    def end(self, episode):
        """Nothing to forget."""

    def proposals(self, views):
        """`Look for cheese`, naming `lactose_free_cheese_eggs` from the second step on."""
        return [Proposal("Look for cheese", ("lactose_free_cheese_eggs",), REASON) if v.step
                else Proposal("Look for cheese") for v in views]


def _rows(backend, domain, tmp_path, questions):
    from adaptbench.training.data import Builder, DataSettings
    from adaptbench.training.relabel import student_policy

    settings = DataSettings(0, ("ron",), ("eggs",), (100,), questions=questions, max_length=None, width=1,
                            max_steps=2)
    store = PairStore(tmp_path)
    Builder(domain, student_policy(backend, domain), settings, store, "tiny", teacher=NamingTeacher()).run()
    return store.rows


@SKIP_MODELS
def test_topics_proposer_asks_about_the_named_preference(backend, domain, tmp_path):
    from adaptbench.agents.users import OfflineUser
    from adaptbench.training.relabel import preference_question, topic_question, topics

    rows = _rows(backend, domain, tmp_path, "topics")
    first, second = sorted(rows, key=lambda r: r["step"])
    assert first["teacher_preferences"] == [] and first["teacher_reason"] is None
    assert first["question"] == topic_question(topics(domain), "Look for cheese", domain.task["eggs"].text)
    assert second["teacher_preferences"] == ["lactose_free_cheese_eggs"] and second["teacher_reason"] == REASON
    pref = next(p for p in domain.persona["ron"].preferences if p.id == "lactose_free_cheese_eggs")
    assert second["question"] == preference_question(pref) == \
        'Ask "Do you have any preference about cheese, lactose-free or eggs?"'
    user = OfflineUser(domain, domain.persona["ron"], domain.task["eggs"])
    assert "lactose_free_cheese_eggs" in user.targets(second["question"][5:-1])  # answered from that preference
    assert second["answer"] == user.answer(second["question"][5:-1])


@SKIP_MODELS
def test_the_student_reflects_with_the_teacher_s_reason(backend, domain, tmp_path, monkeypatch):
    import adaptbench.training.data as data

    seen = []
    own = data.reflection_request

    def spy(student, view, a_s, a_t, made_after=(), reason=None):
        req = own(student, view, a_s, a_t, made_after, reason)
        seen.append((view.step, req.prompt))
        return req
    monkeypatch.setattr(data, "reflection_request", spy)
    rows = _rows(backend, domain, tmp_path, "student")
    by_step = dict(seen)
    assert "would have thought" not in by_step[0]
    assert f"because if the robot knew the user better, it would have thought that '{REASON}'" in by_step[1]
    assert {r["question_source"] for r in rows if r["question"]} == {"student"}


def test_reflection_prompt_carries_the_reason_and_no_example_question(domain):
    from adaptbench.llm.prompts import PromptBuilder, reflection_messages

    ep, made_after = play(domain)
    b = PromptBuilder(domain, "planner")
    with_reason = reflection_messages(b, ep.view(), "Declare Done", "Look for cheese", made_after, REASON)
    last = with_reason[-1]["content"]
    assert f"the robot was expected to perform Look for cheese, because if the robot knew the user better, it " \
           f"would have thought that '{REASON}'" in last
    plain = reflection_messages(b, ep.view(), "Declare Done", "Look for cheese", made_after)[-1]["content"]
    assert "the robot was expected to perform Look for cheese.\n" in plain and "would have thought" not in plain
    tail = plain.split("the robot was expected")[1]
    assert 'Ask "' not in tail  # no example question for a small student to copy


def test_every_preference_question_is_answered_from_its_preference(domain):
    from adaptbench.agents.users import OfflineUser
    from adaptbench.compiler.lint import applies_to
    from adaptbench.training.relabel import preference_question

    for persona in domain.personas:
        for pref in persona.preferences:
            task = next((t for t in domain.tasks if applies_to(domain, pref, t)), None)
            user = OfflineUser(domain, persona, task)
            assert pref.id in user.targets(preference_question(pref)[5:-1]), (persona.id, pref.id)


class ChoiceTeacher(NamingTeacher):
    """NamingTeacher whose second-step proposal also names oracle-ask's question of the choice."""

    def proposals(self, views):
        """As NamingTeacher's, with the eggs' add-ins question from the second step on."""
        return [Proposal(p.action, p.preferences, p.reason, (EGGS_ASK,) if p.preferences else ())
                for p in super().proposals(views)]


EGGS_ASK = "What would you like in or on your eggs, such as vegetables or cheese?"


@SKIP_MODELS
def test_choices_proposer_asks_oracle_ask_s_question_else_as_topics(backend, domain, tmp_path):
    from adaptbench.training.data import Builder, DataSettings
    from adaptbench.training.relabel import student_policy, topic_question, topics

    settings = DataSettings(0, ("ron",), ("eggs",), (100,), questions="choices", max_length=None, width=1,
                            max_steps=2)
    store = PairStore(tmp_path)
    Builder(domain, student_policy(backend, domain), settings, store, "tiny", teacher=ChoiceTeacher()).run()
    first, second = sorted(store.rows, key=lambda r: r["step"])
    assert first["question"] == topic_question(topics(domain), "Look for cheese", domain.task["eggs"].text)
    assert second["question"] == f'Ask "{EGGS_ASK}"' and second["question_source"] == "choices"
    assert EGGS_ASK in {c.ask for r in domain.recipes for c in r.choices}
