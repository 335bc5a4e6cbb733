"""What `adapt play` does with what a person types: the parser's case leniency for the first words
(`look for eggs` reads as `Look for eggs`) and, for a line that is no action, the nearest action form filled
with the words typed and the things the player has seen (`Cook eggs` -> `Cook items in pan_1 to get
cooked_eggs`). A line that is no action never reaches the environment, so it uses no step (docs/agents.md)."""

from __future__ import annotations

import re

_SLOT = re.compile(r"\{(\w+)\}")


def _lead(form: str) -> str:
    """The literal words a form starts with (`Look for`, `Cook items in`); '' for a `{verb} ...` form."""
    return form.split("{", 1)[0].strip()


def fix_case(domain, text: str) -> str:
    """`text` with its leading keyword words spelled as the action form spells them (`LOOK FOR pan` -> `Look
    for pan`) or a verb in lower case (`SCRAMBLE items in ...`); the text unchanged when nothing matches."""
    low = text.lower()
    leads = sorted({_lead(f) for a in domain.actions for f in a.forms if _lead(f)}, key=len, reverse=True)
    for lead in leads:
        if low == lead.lower() or low.startswith(lead.lower() + " "):
            return lead + text[len(lead):]
    first, _, rest = text.partition(" ")
    if first.lower() in domain.verbs:
        return f"{first.lower()} {rest}".strip()
    return text


def _words(text: str) -> list:
    return [w for w in re.findall(r"[a-z]+", text.lower()) if w not in ("a", "an", "the", "some", "of", "to", "in")]


def _stem(w: str) -> str:
    return w[:-1] if w.endswith("s") and len(w) > 3 else w


def _holds(world, eid: str, words: set) -> bool:
    names = [n.name for n in world.contents.get(eid, ())] + list(world.children.get(eid, ()))
    names += list(getattr(world.specs.get(eid), "contents", ()) or ())
    return any(_stem(w) in name for name in names for w in words)


def _best_entity(world, words: set) -> str | None:
    """The seen entity the words most likely mean: seen cookware holding what was named (the pan with the
    eggs), then any seen cookware, then a container holding it, then one named by a word."""
    known = sorted(e for e in world.known if e in world.specs)

    def cookware(e):
        return "cookware" in world.specs[e].tags

    for test in (lambda e: cookware(e) and _holds(world, e, words), cookware,
                 lambda e: _holds(world, e, words), lambda e: any(_stem(w) in e for w in words)):
        hits = [e for e in known if test(e)]
        if hits:
            return hits[0]
    return None


def _past(verb: str) -> str:
    if verb.endswith("e"):
        return verb + "d"
    if re.search(r"[^aeiou]y$", verb):
        return verb[:-1] + "ied"
    return verb + "ed"


def _forms_for(domain, first: str) -> list:
    """The action forms a first word points at: a keyword's forms, else the `{verb}` forms for a verb."""
    forms = [f for a in domain.actions for f in a.forms if _lead(f).split(" ")[0].lower() == first]
    if forms:
        return forms
    if first in domain.verbs:
        return [f for a in domain.actions for f in a.forms if f.startswith("{verb}")]
    return []


def suggest(domain, world, text: str) -> str | None:
    """The nearest action to a line that is no action, filled with what the player typed and has seen; None
    when the first word is no keyword or verb."""
    words = _words(text)
    if not words:
        return None
    forms = _forms_for(domain, words[0])
    if not forms:
        return None
    named = set(words[1:])
    entity = _best_entity(world, named)
    result = "_".join([_past(words[0])] + words[1:3])
    form = min(forms, key=lambda f: (len(_SLOT.findall(f)), len(f)))
    if "to get" in text.lower() or any("to get" in f for f in forms):
        form = next((f for f in forms if "to get" in f and "items in" in f), form)
    filled = {"verb": words[0], "x": entity, "y": entity, "z": result}
    slots = _SLOT.findall(form)
    if "verb" in slots:
        filled.update(y=entity, z=result)
    elif slots and slots[-1] != slots[0]:
        filled[slots[-1]] = result
    out = form
    for s in slots:
        value = filled.get(s) or entity or f"{{{s}}}"
        out = out.replace("{" + s + "}", value, 1)
    return out
