"""Recipe steps, effect values, engine vocabulary, splits and persona numbers are checked when the spec
compiles: each diagnostic code is triggered by a small edit of a copy of the shipped spec, points at the
edited spot and suggests the right name."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from adaptbench.compiler import compile_spec

SPEC = Path(__file__).resolve().parents[2] / "spec"

# file -> [(old, new)]: every edit breaks one thing; one compile reports them all
EDITS = {
    "tasks/recipes.yaml": [
        ('"Move {utensil} to {pan}"', '"Move {utensil} too {pan}"'),                       # D405
        ('- Turn on stove_0', '- Turn on stove_9'),                                         # D407
        ('"Cook items in {pan} to get omelette"', '"Cok items in {pan} to get omelette"'),  # D406
        ('{when: {style: [poach]}, do: ["Pour water', '{when: {style: [poch]}, do: ["Pour water'),  # D409
        ("options: [bowl_4, bowl_0, bowl_8, bowl_12, bowl_13]",
         "options: [bowl_4, bowl_0, bowl_88, bowl_12, bowl_13]"),                          # D408
        ("- ADD {yoghurt} TO {bowl}", "- ADD {yoghurt} INTO {bowl}"),                       # D405 (ADD)
        ('"Pour coffee from coffee_machine_0 into {cup}"',
         '"Pour cofee from coffee_machine_0 into {cup}"'),                                  # D407
        ("{for: toppings, do: [\"ADD {item} TO {bowl}\"]}\n\n  - id: parfait",
         "{for: milk, do: [\"ADD {item} TO {bowl}\"]}\n\n  - id: parfait"),                # D409 (for)
        ("      - ADD {tea} TO {cup}", "      - ADD {tee} TO {cup}"),                      # D404
    ],
    "tasks/tasks.yaml": [("components: [eggs]}", "components: [eggs, pancakes]}")],        # D410
    "actions/appliances.yaml": [('state: "on"}', 'state: "onn"}')],                         # D205
    "actions/cooking.yaml": [("verb: cook, heat: always}", "verb: cook, heat: allways}")],  # D205
    "actions/containers.yaml": [('reveal_in: {place: "{x}", intro: Opened}',
                                 'reveal_in: {place: fridge_9, intro: Opened}')],           # D205
    "tasks/components.yaml": [("kind: beverage", "kind: beverages")],                       # D502
    "engine.yaml": [("dining_place: dining_place", "dining_place: dinning_place"),          # D502
                    ("sweetener, fruit", "sweetener, fruits"),                              # D502
                    ("result_tags: [edible, food]", "result_tags: [edibel, food]")],        # D502
    "splits.yaml": [("[carlos, jamal, juan, maria]", "[carlos, jamall, juan, maria]"),     # D601, D602
                    ("[miranda, rachel, ron, sarah]", "[miranda, rachel, ron, sarah, lisa]")],  # D602
    "personas/lisa.yaml": [("\nnumber: 3\n", "\nnumber: 1\n")],                             # D303
}


def _copy(tmp: Path, edits: dict) -> Path:
    spec = tmp / "spec"
    shutil.copytree(SPEC, spec)
    for rel, pairs in edits.items():
        path = spec / rel
        text = path.read_text()
        for old, new in pairs:
            assert old in text, (rel, old)
            text = text.replace(old, new, 1)
        path.write_text(text)
    return spec


@pytest.fixture(scope="module")
def diags(tmp_path_factory):
    spec = _copy(tmp_path_factory.mktemp("broken"), EDITS)
    domain, out = compile_spec([spec])
    assert domain is None
    return [(Path(d.path).resolve().relative_to(spec.resolve()).as_posix(), d.line, d.col, d.code, d.message, d.severity) for d in out]


def _find(diags, code: str, *words) -> tuple:
    hits = [d for d in diags if d[3] == code and all(w in d[4] for w in words)]
    assert hits, f"no {code} with {words} in:\n" + "\n".join(map(str, diags))
    return hits[0]


def _line_of(rel: str, text: str) -> int:
    spec_text = (SPEC / rel).read_text().splitlines()
    return next(i for i, ln in enumerate(spec_text, 1) if text in ln)


CASES = [
    ("D404", ("unknown choice 'tee'", "did you mean 'tea'")),
    ("D405", ("'Move {utensil} too {pan}' does not read as any action", "closest form: 'Move {x} to {y}'")),
    ("D405", ("ADD <what> TO <vessel>",)),
    ("D406", ("'Cok' is not a declared verb", "did you mean 'Cook'")),
    ("D407", ("'stove_9' is not an entity", "did you mean 'stove_0'")),
    ("D407", ("'cofee'", "did you mean 'coffee'")),
    ("D408", ("option 'bowl_88' of choice 'bowl'", "did you mean 'bowl_8'")),
    ("D409", ("'poch' is not an option of 'style'", "did you mean 'poach'")),
    ("D409", ("'for: milk' loops over a single choice",)),
    ("D410", ("no recipe makes component 'pancakes'",)),
    ("D205", ("state 'onn'", "did you mean 'on'")),
    ("D205", ("heat 'allways'", "did you mean 'always'")),
    ("D205", ("place 'fridge_9'", "did you mean 'fridge_0'")),
    ("D502", ("unknown kind 'beverages'", "did you mean 'beverage'")),
    ("D502", ("dining_place 'dinning_place'", "did you mean 'dining_place'")),
    ("D502", ("swap family 'fruits'", "did you mean 'fruit'")),
    ("D502", ("result_tags: 'edibel'", "did you mean 'edible'")),
    ("D601", ("unknown persona 'jamall'", "did you mean 'jamal'")),
    ("D602", ("'lisa' is unseen in split 0 and again in split 3",)),
    ("D602", ("'jamal' is unseen in no split",)),
    ("D303", ("persona number 1 is already used by 'juan'",)),
]


@pytest.mark.parametrize(("code", "words"), CASES, ids=[f"{c}-{w[0][:24]}" for c, w in CASES])
def test_each_code_is_reported(diags, code, words):
    _find(diags, code, *words)


def test_step_errors_point_at_the_word(diags):
    rel, line, col, *_ = _find(diags, "D407", "'stove_9'")
    assert rel == "tasks/recipes.yaml" and line == _line_of(rel, "- Turn on stove_0")
    src = (SPEC / rel).read_text().splitlines()[line - 1]
    assert src[col - 1:].startswith("stove_0")  # the column of the bad id itself
    rel, line, col, *_ = _find(diags, "D406", "'Cok'")
    src = (SPEC / rel).read_text().splitlines()[line - 1]
    assert src[col - 1:].startswith("Cook items in {pan}")


def test_effect_value_points_at_the_parameter(diags):
    rel, line, col, *_ = _find(diags, "D205", "'onn'")
    assert rel == "actions/appliances.yaml" and line == _line_of(rel, 'state: "on"}')
    assert (SPEC / rel).read_text().splitlines()[line - 1][col - 1:].startswith('"on"')


def test_shared_steps_are_reported_once(diags):
    """eggs and omelette share their steps through a YAML anchor: one diagnostic, not two."""
    assert len([d for d in diags if d[3] == "D406"]) == 1


def test_missing_recipe_is_only_a_warning(tmp_path):
    spec = _copy(tmp_path, {"tasks/tasks.yaml": EDITS["tasks/tasks.yaml"]})
    domain, out = compile_spec([spec])
    assert domain is not None
    assert [d.code for d in out if d.code == "D410"] == ["D410"] and all(d.severity == "warning" for d in out)


def test_missing_engine_file(tmp_path):
    spec = _copy(tmp_path, {})
    (spec / "engine.yaml").unlink()
    domain, out = compile_spec([spec])
    assert domain is None and [d.code for d in out if d.severity == "error"] == ["D501"]


def test_shipped_spec_carries_engine_and_splits(domain):
    assert domain.engine.dining_place == "dining_place" and domain.engine.opposite("on") == "off"
    assert domain.unseen[1] == ("carlos", "jamal", "juan", "maria")
    held_out = [p for s in domain.splits for p in s.unseen]
    assert sorted(held_out) == sorted(domain.persona) and len(domain.splits) == 4
    assert all(len(s.unseen) == 4 for s in domain.splits)
    assert len({p.number for p in domain.personas}) == len(domain.personas)
