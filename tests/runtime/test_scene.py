"""Scene sampling is seeded, keeps everything mandatory, and drops about 30% of the rest."""

from __future__ import annotations

import shutil
from pathlib import Path

import yaml

from adaptbench.compiler import load_domain
from adaptbench.runtime.env import Env
from adaptbench.runtime.scene import sample_scene

SPEC = Path(__file__).resolve().parents[2] / "spec"


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


def _append_objects(spec: Path) -> set:
    """Append new optional objects at the start, middle and end of catalogue files; return their ids."""
    new = {}
    new["pantry.yaml"] = [("chia_pack_0", "pack of chia seeds", "counter_0", 0),
                          ("chia_pack_1", "another pack of chia seeds", "cabinet_0", None)]
    new["tableware.yaml"] = [("chia_pack_2", "a third pack of chia seeds", "counter_1", 3)]
    ids = set()
    for name, items in new.items():
        path = spec / "objects" / name
        data = yaml.safe_load(path.read_text())
        for eid, desc, loc, pos in items:
            obj = {"id": eid, "description": desc, "category": "box", "location": loc,
                   "tags": ["container", "source"], "contents": ["salt"]}
            data["objects"].insert(len(data["objects"]) if pos is None else pos, obj)
            ids.add(eid)
        path.write_text(yaml.safe_dump(data, sort_keys=False))
    return ids


def test_adding_objects_anywhere_changes_no_other_object(domain, tmp_path):
    spec = tmp_path / "spec"
    shutil.copytree(SPEC, spec)
    new = _append_objects(spec)
    extended = load_domain(spec, use_cache=False)
    assert extended.spec_hash != domain.spec_hash
    for seed in range(100):
        before, after = sample_scene(domain, seed), sample_scene(extended, seed)
        assert before.present == after.present - new, seed
        assert dict(before.location) == {e: h for e, h in after.location if e not in new}, seed
        if not new & after.present:
            assert before.scene_id == after.scene_id, seed


def test_scene_id_is_a_hash_of_the_scene_not_the_spec(domain, tmp_path):
    spec = tmp_path / "spec"
    shutil.copytree(SPEC, spec)
    path = spec / "tasks" / "tasks.yaml"
    path.write_text("# an edit that changes the spec hash only\n" + path.read_text())
    edited = load_domain(spec, use_cache=False)
    assert edited.spec_hash != domain.spec_hash
    assert [sample_scene(edited, s).scene_id for s in range(5)] == [sample_scene(domain, s).scene_id for s in range(5)]
