"""Hostile spec variants for the fuzzer: each is a change to a copy of the shipped spec that must give
a located diagnostic (exit 1), never a hang, a traceback, a crash or gigabytes of memory.

A variant is (name, edits, expected): edits map a path under the spec to new bytes (b"" + APPEND
prefix appends; None removes; a `(old, new)` pair replaces the first occurrence), and `expected`
is a regular expression the diagnostics must match.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

HOSTILE = "objects/zz_hostile.yaml"
APPEND = b"\x00APPEND\x00"


def _obj(ident: str, location: str, extra: str = "") -> str:
    return (f"  - id: {ident}\n    description: box {ident}\n    category: pan\n    location: {location}\n"
            f"    tags: [container]\n{extra}")


def _objects(*items: str) -> bytes:
    return ("objects:\n" + "".join(items)).encode()


def _raw(text) -> dict:
    return {HOSTILE: text if isinstance(text, bytes) else text.encode()}


def _bomb(levels: int, width: int) -> str:
    lines = [f"a0: &a0 [{', '.join(['x'] * width)}]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]")
    return "\n".join(lines) + "\n"


def _rule(rule: str) -> dict:
    return {"personas/juan.yaml": ('rule: "for egg_dish: it is scrambled | omelette"', f"rule: {rule!r}".replace(
        "'", '"') if '"' not in rule else f"rule: '{rule}'")}


def _action(field: str, old: str, new: str) -> dict:
    return {"actions/containers.yaml": (f'{field}: "{old}"', f'{field}: "{new}"')}


# The meaning, not one PyYAML release's wording: a located spec error (S0xx) that says the document nests
# too deep (6.0.3's composer and our token scan say "too deep"; 6.0.4's scanner says "maximum nesting depth").
NESTED = r"error\[S0\d\d\]: .*(nest|deep)"

VARIANTS = [
    # cycles and ids
    ("cycle of two", _raw(_objects(_obj("box_a", "box_b"), _obj("box_b", "box_a"))), r"cycle.*box_a"),
    ("cycle of three", _raw(_objects(_obj("box_a", "box_b"), _obj("box_b", "box_c"), _obj("box_c", "box_a"))),
     r"cycle.*box_a.*box_b.*box_c"),
    ("cycle with a tail", _raw(_objects(_obj("box_t", "box_a"), _obj("box_a", "box_b"), _obj("box_b", "box_a"))),
     r"cycle"),
    ("self location", _raw(_objects(_obj("box_a", "box_a"))), r"box_a"),
    ("cycle through a shipped object", {"objects/cookware.yaml": ("location: cabinet_3", "location: box_z"),
                                        HOSTILE: _objects(_obj("box_z", "pan_0"))}, r"cycle"),
    ("id with a trailing newline", _raw(_objects(_obj('"box_n\\n"', "cabinet_3"))), r"S104"),
    ("id as a block scalar", _raw("objects:\n  - id: |\n      box_n\n    description: d\n    category: pan\n"
                                  "    location: cabinet_3\n"), r"S104"),
    ("persona id with a trailing newline", {"personas/juan.yaml": ("id: juan", 'id: "juan\\n"')}, r"S104"),
    ("homoglyph id", _raw(_objects(_obj("p\u0430n_9", "cabinet_3"))), r"S104"),
    # YAML structure
    ("alias bomb 9x9", _raw(_bomb(9, 9)), r"alias"),
    ("alias bomb 30x2", _raw(_bomb(30, 2)), r"alias"),
    ("recursive alias", _raw("a: &a [*a]\n"), r"alias|recurs|deep"),
    ("recursive alias in a mapping", _raw("a: &a {b: *a}\n"), r"alias|recurs|deep"),
    ("flow nesting 100000", _raw("objects: " + "[" * 100_000 + "]" * 100_000 + "\n"), NESTED),
    ("flow mapping nesting 100000", _raw("objects: " + "{a: " * 100_000 + "1" + "}" * 100_000 + "\n"), NESTED),
    ("block sequence nesting 50000", _raw("objects:\n" + "- " * 50_000 + "x\n"), NESTED),
    ("indentation nesting 400", _raw("".join("  " * i + f"k{i}:\n" for i in range(400)) + "  " * 400 + "v\n"),
     r"deep"),
    ("flow nesting 70", _raw("objects: " + "[" * 70 + "]" * 70 + "\n"), NESTED),
    ("mixed nesting", _raw("objects:\n" + "- " * 150 + "[" * 60 + "]" * 60 + "\n"), NESTED),
    ("python tag", _raw('objects: !!python/object/apply:os.system ["echo pwned"]\n'), r"tag"),
    ("python name tag", _raw("objects: !!python/name:os.system\n"), r"tag"),
    ("local tag", _raw("objects: !foo bar\n"), r"tag"),
    ("local tag on a mapping", _raw("objects: !thing {a: 1}\n"), r"tag"),
    ("local tag on a sequence", _raw("objects: !thing [1]\n"), r"tag"),
    ("binary tag", _raw("objects: !!binary aGVsbG8=\n"), r"tag"),
    ("set tag", _raw("objects: !!set {a, b}\n"), r"tag"),
    ("omap tag", _raw("objects: !!omap [a: 1]\n"), r"tag"),
    ("verbatim tag", _raw("objects: !<tag:example.com,2000:x> 1\n"), r"tag"),
    ("merge key", _raw("base: &b {category: pan}\nobjects:\n  - <<: *b\n    id: box_m\n"), r"merge"),
    ("merge key list", _raw("b1: &b1 {x: 1}\nobjects:\n  - <<: [*b1]\n"), r"merge"),
    ("sequence as a key", _raw("? [a, b]\n: 1\n"), r"key"),
    ("mapping as a key", _raw("{a: 1}: 2\n"), r"key"),
    ("nested complex key", _raw("objects:\n  - ? {id: x}\n    : 1\n"), r"key"),
    ("null key", _raw("~: 1\nobjects: []\n"), r"error"),
    ("date value", _raw(_objects(_obj("box_d", "cabinet_3").replace("description: box box_d",
                                                                     "description: 2001-12-14"))), r"error"),
    ("NUL byte", _raw(b"objects:\n  - id: box\x00_0\n"), r"NUL|control"),
    ("NUL byte in an actions file", {"actions/containers.yaml": ("Opened {x}", "Opened\x00 {x}")}, r"NUL|control"),
    ("bell character", _raw(b"objects: [\x07]\n"), r"control"),
    ("escape character", _raw(b"objects:\n  - id: a\x1b[31m\n"), r"control"),
    ("latin-1 byte in actions", {"actions/containers.yaml": ("cannot be opened", "ne s'ouvre pas \xe9")}, r"UTF-8"),
    ("UTF-16 file", {HOSTILE: "objects: []\n".encode("utf-16")}, r"UTF-8|NUL|control"),
    ("lone surrogate escape", _raw('objects: ["\\ud800"]\n'), r"error"),
    ("tabs for indentation", _raw("objects:\n\t- id: x\n"), r"tab|YAML"),
    ("two documents", _raw("objects: []\n---\nobjects: []\n"), r"document"),
    ("top-level list", _raw("- a\n- b\n"), r"mapping"),
    ("top-level scalar", _raw("hello\n"), r"mapping"),
    ("huge integer 5000 digits", {"personas/juan.yaml": ("number: 1", "number: " + "9" * 5000)}, r"number|large"),
    ("huge integer 40 digits", {"personas/juan.yaml": ("number: 1", "number: " + "9" * 40)}, r"number|large"),
    ("huge hex integer", {"personas/juan.yaml": ("number: 1", "number: 0x" + "f" * 5000)}, r"number|large"),
    ("infinite float", {"personas/juan.yaml": ("number: 1", "number: 1e999")}, r"number|finite|integer"),
    ("nan", {"personas/juan.yaml": ("number: 1", "number: .nan")}, r"number|finite|integer"),
    ("negative huge", {"personas/juan.yaml": ("number: 1", "number: -" + "9" * 30)}, r"number|large"),
    # every place the spec takes a number: a persona's `number` (above), a split's `id`, a count in a rule
    ("huge split id", {"splits.yaml": ("id: 0", "id: " + "9" * 5000)}, r"S014.*number|large"),
    ("negative huge split id", {"splits.yaml": ("id: 0", "id: -" + "9" * 5000)}, r"S014.*number|large"),
    ("infinite split id", {"splits.yaml": ("id: 0", "id: .inf")}, r"split|integer|number"),
    ("huge count in a rule 5000 digits", _rule("for savory: count(it, spice) >= " + "9" * 5000),
     r"D111.*out of range"),
    ("huge count in a rule 40 digits", _rule("for savory: count(it, spice) > " + "9" * 40), r"D111.*out of range"),
    ("count in a rule just over the limit", _rule("for savory: count(it, spice) > 1000001"), r"D111"),
    ("exponent count in a rule", _rule("for savory: count(it, spice) > 1e999"), r"R001"),
    ("negative count in a rule", _rule("for savory: count(it, spice) > -1"), r"R001"),
    ("huge float in a list", _raw("objects: [" + "9" * 400 + ".5]\n"), r"error"),
    ("duplicate key", {"personas/juan.yaml": ("name: Juan", "name: Juan\nname: Juan")}, r"S001"),
    # rules
    ("rule nested 500 deep", _rule("for egg_dish: it is " + "(" * 500 + "scrambled" + ")" * 500), r"nest"),
    ("rule nested 5000 deep", _rule("for egg_dish: it is " + "(" * 5000 + "scrambled" + ")" * 5000), r"nest"),
    ("rule with 3000 nots", _rule("for egg_dish: " + "not " * 3000 + "it is scrambled"), r"nest|long"),
    ("rule 20000 alternatives", _rule("for egg_dish: it is " + " | ".join(["scrambld"] * 20000)), r"error"),
    ("rule with a NUL", _rule("for egg_dish: it is scr\\u0000ambled"), r"error"),
    ("unbalanced rule", _rule("for egg_dish: it is ((scrambled"), r"error"),
    # message templates
    ("unknown slot in success", _action("success", "Opened {x}", "Opened {q}"), r"slot.*q"),
    ("broken brace in success", _action("success", "Opened {x}", "Opened {x"), r"brace"),
    ("stray closing brace in fail", _action("fail", "{x} cannot be opened", "{x}} cannot be opened"), r"brace"),
    ("positional field in success", _action("success", "Opened {x}", "Opened {0}"), r"slot"),
    ("attribute access in success", _action("success", "Opened {x}", "Opened {x.__class__}"), r"slot"),
    ("conversion in success", _action("success", "Opened {x}", "Opened {x!r}"), r"slot|conversion"),
    ("format spec in fail", _action("fail", "{x} cannot be opened", "{x:>999999999} cannot be opened"),
     r"slot|format"),
    ("unknown slot in an effect", {"actions/containers.yaml": ('target: "{x}", state: open',
                                                               'target: "{nope}", state: open')}, r"slot.*nope"),
    # files
    ("directory named like a spec file", {"objects/dir.yaml/": b""}, r"dir\.yaml"),
    ("symlink loop", {"objects/loop.yaml": "->loop.yaml"}, r"loop\.yaml"),
    ("dangling symlink", {"objects/gone.yaml": "->nowhere.yaml"}, r"gone\.yaml"),
]


def make_spec(src: Path, dst: Path, edits: dict) -> Path:
    """Copy the spec at `src` to `dst` and apply `edits`."""
    shutil.copytree(src, dst)
    for rel, change in edits.items():
        path = dst / rel
        if rel.endswith("/"):
            path.mkdir(parents=True)
        elif isinstance(change, str) and change.startswith("->"):
            os.symlink(change[2:], path)
        elif isinstance(change, tuple):
            old, new = change
            text = path.read_bytes()
            old_b, new_b = (x.encode("latin-1") if "\xe9" in x else x.encode() for x in (old, new))
            assert old_b in text, f"{rel}: {old!r} not found"
            path.write_bytes(text.replace(old_b, new_b, 1))
        else:
            path.write_bytes(change)
    return dst
