"""Every `Look for` category the grammar accepts is a word a person would type: plurals only of countable
nouns (the last word of a phrase), the irregular ones right, never a plural of a plural or of an adjective."""

from __future__ import annotations

import re

from adaptbench.grammars.index import countable, plural


def test_plural_takes_the_last_word_and_irregular_forms():
    assert plural("egg") == "eggs" and plural("berry") == "berries" and plural("peach") == "peaches"
    assert plural("bread knife") == "bread knives" and plural("tomato") == "tomatoes"
    assert plural("loaf") == "loaves" and plural("glass") == "glasses" and plural("avocado") == "avocados"
    nouns = frozenset({"egg", "eggs", "chair", "milk", "dining", "table"} - {"dining"})
    assert countable("egg", nouns) and countable("dining table", nouns)
    assert not countable("eggs", nouns)  # already a plural
    assert not countable("milk", nouns)  # a mass noun
    assert not countable("wooden dining", nouns)  # an adjective last


def test_every_category_is_a_word_a_person_would_type(index, domain):
    cats = set(index.categories)
    for made_up in ("eggses", "chairses", "wooden dinings", "knifes", "milks", "tomatos", "waters", "freshes", "sweets"):
        assert made_up not in cats, made_up
    for real in ("eggs", "chairs", "knives", "tomatoes", "glasses", "berries", "plates", "bowls", "spices", "fruits"):
        assert real in cats, real
    nouns = {e.category.rsplit("_", 1)[-1] for e in domain.entities} | {
        s.category.rsplit("_", 1)[-1] for s in domain.substances} | {
        re.sub(r"_\d+$", "", e.id).rsplit("_", 1)[-1] for e in domain.entities} | {
        t.rsplit("_", 1)[-1] for x in (*domain.entities, *domain.substances) for t in x.tags}
    said = _described(domain)
    for p in cats:
        if p in said:
            continue  # a word or word pair of the catalogue itself
        stem = next((b for b in cats if plural(b) == p), None)  # so p is a made plural: of what?
        assert stem is not None, p
        last = stem.rpartition(" ")[2]
        assert last in nouns and not re.search(r"[^s]s$", last), (p, stem)  # a singular noun, not `eggs`


def _described(domain) -> set:
    words = set()
    for spec in (*domain.entities, *domain.substances):
        w = re.findall(r"[a-z]+", spec.description.lower())
        words |= set(w) | {f"{a} {b}" for a, b in zip(w, w[1:], strict=False)}
        words |= {t.replace("_", " ") for t in spec.tags} | {t.rsplit("_", 1)[-1] for t in spec.tags}
        words |= {spec.category.replace("_", " ")} | {c.replace("_", " ") for c in getattr(spec, "contents", ())}
        words.add(re.sub(r"_\d+$", "", spec.id).replace("_", " "))
    return words


def test_the_runtime_search_reads_the_irregular_plurals(domain):
    from adaptbench.runtime.env import Env

    env = Env(domain, task="eggs", persona="juan", full_scene=True)
    env.reset()
    r = env.step("Look for knives")
    assert r.ok and "knife" in r.observation, r.observation
