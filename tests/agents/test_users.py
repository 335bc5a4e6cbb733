"""The offline user: picks the preference a question is about, is consistent, never says where things are."""

from __future__ import annotations

from adaptbench.agents.users import NO_LOCATION, NO_PREFERENCE, OfflineUser, first_person, words
from adaptbench.compiler.model import Persona, Preference
from adaptbench.compiler.rules import parse_rule


def _persona():
    prefs = (
        Preference("black_coffee", "Coffee black, without milk or sugar", parse_rule("for coffee: it has no creamer"),
                   ("coffee", "milk", "sugar", "black"), "I take my coffee black."),
        Preference("patio", "Prefers to dine on the patio", parse_rule("for all: it served at patio"),
                   ("where to eat", "table", "patio", "serve"), "I like to eat on the patio."),
        Preference("scrambled", "Eggs must be scrambled", parse_rule("for eggs: it is scrambled"),
                   ("eggs", "scrambled", "cooking style"), ""),
    )
    return Persona("zed", "Zed", 99, "", prefs)


def test_question_is_answered_with_the_matching_preference(domain):
    user = OfflineUser(domain, _persona(), domain.task["toast_coffee"])
    assert user.answer("How do you take your coffee? Any milk or sugar?") == "I take my coffee black."
    assert user.answer("Where would you like to eat, at the table or on the patio?") == "I like to eat on the patio."


def test_missing_answer_falls_back_to_first_person_text(domain):
    user = OfflineUser(domain, _persona(), domain.task["eggs"])
    assert user.answer("How do you like your eggs cooked?") == "I'd like this: eggs must be scrambled."


def test_flexible_when_no_preference(domain):
    user = OfflineUser(domain, _persona(), domain.task["eggs"])
    assert user.answer("Do you like jazz music?") == NO_PREFERENCE


def test_never_reveals_locations(domain):
    user = OfflineUser(domain, _persona(), domain.task["eggs"])
    for q in ("Where is the coffee?", "Where can I find the milk?", "Which cabinet has the mugs?"):
        assert user.answer(q) == NO_LOCATION


def test_same_question_same_answer(domain):
    user = OfflineUser(domain, _persona(), domain.task["eggs"])
    a = user.answer("Any milk in your coffee?")
    assert all(user.answer("Any milk in your coffee?") == a for _ in range(3))


def test_words_and_first_person():
    assert words("The Eggs, scrambled!") == {"egg", "scrambled"}
    assert first_person("Prefers tea hot") == "I prefer tea hot."
