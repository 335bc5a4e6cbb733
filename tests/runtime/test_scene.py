"""Scene sampling is seeded, keeps everything mandatory, and drops about 30% of the rest."""

from __future__ import annotations

from adaptbench.runtime.env import Env
from adaptbench.runtime.scene import sample_scene


def test_same_seed_same_scene_different_seed_different_scene(domain):
    a, b, c = sample_scene(domain, 1), sample_scene(domain, 1), sample_scene(domain, 2)
    assert a == b and a.scene_id == b.scene_id
    assert a.present != c.present and a.scene_id != c.scene_id


def test_mandatory_rooms_and_furniture_always_present(domain):
    for seed in range(20):
        s = sample_scene(domain, seed)
        for e in domain.entities:
            if e.kind != "movable" or e.mandatory:
                assert e.id in s.present


def test_about_seventy_percent_of_optional_movables(domain):
    optional = [e.id for e in domain.entities if e.kind == "movable" and not e.mandatory]
    kept = sum(len(set(optional) & sample_scene(domain, seed).present) for seed in range(40))
    assert 0.66 < kept / (40 * len(optional)) < 0.74


def test_orphans_move_to_the_nearest_present_holder(domain):
    for seed in range(30):
        s = sample_scene(domain, seed)
        loc = dict(s.location)
        for _e, holder in loc.items():
            assert holder is None or holder in s.present


def test_full_scene_has_everything(domain):
    assert len(sample_scene(domain, None, full=True).present) == len(domain.entities)


def test_agent_starts_with_the_layout_only(domain):
    env = Env(domain, task="eggs", seed=0)
    text = env.reset()
    assert "- kitchen (kitchen)" in text and "  - fridge_0 (fridge)" in text
    assert "egg_0" not in text and "milk_0" not in text
    assert "sink_1 (standard kitchen sink, contains water)" in text
