"""World state during an episode: where everything is, what containers hold, and provenance.

Every edible thing is a provenance `Node`: a movable object (egg_0), a portion of a substance
(whole_milk poured from milk_0), or a result of an action (`to get scrambled_eggs`) whose
`inputs` are the nodes it was made from. Nodes record when they were heated and cut, in which
vessels, and the last step they arrived in a container, which is what the verifiers query.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..compiler.model import CompiledDomain, EntitySpec
from .scene import Scene
from .tables import domain_tables


class Node:
    """One edible thing's provenance record (mutable during the episode)."""

    __slots__ = ("nid", "name", "category", "tags", "inputs", "verb", "created", "heated", "cut",
                 "vessels", "arrived", "entity", "wet", "chilled")

    def __init__(self, nid, name, category, tags, inputs=(), verb=None, created=0, entity=None):
        self.nid = nid
        self.name = name
        self.category = category
        self.tags = tags
        self.inputs = inputs
        self.verb = verb
        self.created = created
        self.heated: list = []  # steps at which it was heated
        self.wet: tuple = ()  # steps at which it was heated whole in water (an egg boiled in its shell)
        self.chilled: tuple = ()  # steps at which it was put in a fridge or freezer
        self.cut = False
        self.vessels: set = set()  # entity ids it was heated or made in
        self.arrived = created  # last step it was put into a container
        self.entity = entity  # the object id when the node is a movable object

    def __repr__(self) -> str:
        return f"Node({self.name}#{self.nid})"


@dataclass
class Event:
    """One step of the trace."""

    step: int
    text: str
    action: str | None
    ok: bool
    observation: str
    args: dict = field(default_factory=dict)
    reply: str = ""


@dataclass
class _Template:
    """What every episode on one scene starts from (built once per scene)."""

    specs: dict
    parent: dict
    children: dict
    sources: dict
    source_index: dict
    known: frozenset
    known_contents: frozenset
    edible: tuple


def _template(domain: CompiledDomain, scene: Scene) -> _Template:
    return domain_tables(domain).world_templates.get_or_build(scene.scene_id, lambda: _build_template(domain, scene))


def _build_template(domain: CompiledDomain, scene: Scene) -> _Template:
    specs = {e.id: e for e in domain.entities if e.id in scene.present}
    children: dict = {e: [] for e in specs}
    for e, loc in scene.location:
        if loc is not None:
            children[loc].append(e)
    sources = {e: s.contents for e, s in specs.items() if s.contents}
    index: dict = {}
    for e in sorted(sources):
        for sub in sources[e]:
            index.setdefault(sub, []).append(e)
    known = frozenset(e for e, s in specs.items() if s.kind != "movable")
    t = _Template(specs, dict(scene.location), children, sources, index, known,
                  frozenset(c for e in known for c in specs[e].contents),
                  tuple((e, s.category, frozenset(s.tags)) for e, s in specs.items() if "edible" in s.tags))
    return t


class World:
    """The mutable state of one episode over a scene of a compiled domain."""

    def __init__(self, domain: CompiledDomain, scene: Scene):
        self.domain = domain
        self.scene = scene
        t = _template(domain, scene)
        self.specs: dict[str, EntitySpec] = dict(t.specs)
        self.parent: dict[str, str | None] = dict(t.parent)
        self.children: dict[str, list] = {k: list(v) for k, v in t.children.items()}
        self.sources: dict[str, tuple] = t.sources  # never changed during an episode
        self.source_index: dict[str, list] = t.source_index
        self.contents: dict[str, list] = {}
        self.state: dict[str, set] = {}
        self.arrived: dict[str, int] = {}
        self.known: set = set(t.known)
        self.known_contents: set = set(t.known_contents)
        self.used: set = set()
        self.step = 0
        self.trace: list[Event] = []
        self.questions = 0
        self.done = False
        self._nid = 0
        self.nodes: dict[str, Node] = {}  # edible objects' nodes
        self.fill_log: dict[str, list] = {}  # container -> [(step, holds food after it)], from its first change
        self._touched: set = set()  # containers whose food may have changed in this step
        for e, category, tags in t.edible:
            self.nodes[e] = self.new_node(e, category, tags, entity=e)

    # ---- nodes
    def new_node(self, name, category, tags, inputs=(), verb=None, entity=None) -> Node:
        """Create a provenance node at the current step."""
        self._nid += 1
        return Node(self._nid, name, category, tags, inputs, verb, self.step, entity)

    def portion(self, substance: str) -> Node:
        """A fresh portion of a substance taken from an endless source."""
        s = self.domain.substance[substance]
        return self.new_node(substance, s.category, frozenset(s.tags))

    # ---- queries
    def exists(self, eid: str) -> bool:
        """Whether entity `eid` is in the world now."""
        return eid in self.specs

    def tags(self, eid: str) -> tuple:
        """The tags of an entity."""
        return self.specs[eid].tags

    def is_container(self, eid: str) -> bool:
        """Whether things can be put in or on `eid`."""
        return "container" in self.specs[eid].tags

    def ancestors(self, eid: str):
        """Holders of `eid`, innermost first."""
        loc = self.parent.get(eid)
        while loc is not None:
            yield loc
            loc = self.parent.get(loc)

    def room_of(self, eid: str) -> str | None:
        """The room an entity is in."""
        if self.specs[eid].kind == "room":
            return eid
        for a in self.ancestors(eid):
            if self.specs[a].kind == "room":
                return a
        return None

    def holders_of(self, name: str) -> list:
        """Known entities holding content `name` (as a portion or as an endless source), sorted."""
        out = {e for e in self.source_index.get(name, ()) if e in self.known}
        out.update(e for e, nodes in self.contents.items()
                   if e in self.known and any(n.name == name for n in nodes))
        return sorted(out)

    def has_content(self, holder: str, name: str) -> bool:
        """Whether `holder` holds content `name`."""
        return name in self.sources.get(holder, ()) or any(n.name == name for n in self.contents.get(holder, ()))

    def content_names(self, eid: str) -> list:
        """Names of everything `eid` holds as contents, sources first."""
        names = list(self.sources.get(eid, ()))
        for n in self.contents.get(eid, ()):
            if n.name not in names:
                names.append(n.name)
        return names

    def descendants(self, eid: str):
        """Every entity inside `eid`, at any depth."""
        for c in self.children.get(eid, ()):
            yield c
            yield from self.descendants(c)

    def holds_food(self, eid: str) -> bool:
        """Whether `eid` holds food now: a content, or an edible object standing in or on it."""
        return bool(self.contents.get(eid)) or any(c in self.nodes for c in self.children.get(eid, ()))

    def held_food(self, eid: str, step: int) -> bool:
        """Whether `eid` held food after `step` (docs/rules.md, *Free: availability that counts use*)."""
        log = self.fill_log.get(eid)
        if not log:
            return self.holds_food(eid)  # never changed: as it is now
        held = log[0][1]
        for s, full in log:
            if s > step:
                break
            held = full
        return held

    def filled_at(self, eid: str) -> int:
        """The step `eid` last went from holding no food to holding some (0: it held food from the start)."""
        log = self.fill_log.get(eid, ())
        for i in range(len(log) - 1, 0, -1):
            if log[i][1] and not log[i - 1][1]:
                return log[i][0]
        return 0

    def settle(self) -> None:
        """After a step: log the containers whose holding food changed in it (`held_food`, `filled_at`)."""
        for eid in self._touched:
            log = self.fill_log[eid]
            now = self.holds_food(eid)
            if log[-1][1] != now:
                log.append((self.step, now))
        self._touched.clear()

    def _touch(self, eid: str | None) -> None:
        if eid is not None and eid not in self._touched:
            self._touched.add(eid)
            if eid not in self.fill_log:
                self.fill_log[eid] = [(0, self.holds_food(eid))]

    # ---- changes
    def relocate(self, eid: str, target: str) -> None:
        """Move entity `eid` into/onto `target` (where it already is: nothing changes, it does not re-arrive)."""
        old = self.parent.get(eid)
        if old == target:
            return
        if eid in self.nodes:
            self._touch(old)
            self._touch(target)
        if old is not None:
            self.children[old].remove(eid)
        self.parent[eid] = target
        self.children[target].append(eid)
        self.arrived[eid] = self.step
        if eid in self.nodes:
            self.nodes[eid].arrived = self.step

    def remove(self, eid: str) -> None:
        """Remove an entity that was consumed or transformed."""
        for c in list(self.children.get(eid, ())):
            self.relocate(c, self.parent[eid])
        if eid in self.nodes:
            self._touch(self.parent.get(eid))
        old = self.parent.pop(eid, None)
        if old is not None:
            self.children[old].remove(eid)
        self.children.pop(eid, None)
        self.specs.pop(eid, None)
        self.nodes.pop(eid, None)
        self.known.discard(eid)

    def add_entity(self, spec: EntitySpec, node: Node, holder: str) -> None:
        """Add a new (result) object entity at `holder`."""
        self._touch(holder)
        self.specs[spec.id] = spec
        self.children[spec.id] = []
        self.nodes[spec.id] = node
        node.entity = spec.id
        self.parent[spec.id] = holder
        self.children[holder].append(spec.id)
        self.arrived[spec.id] = self.step
        self.known.add(spec.id)

    def take_contents(self, holder: str, name: str) -> list:
        """Remove and return the portions named `name` from `holder` (a new portion from a source)."""
        nodes = [n for n in self.contents.get(holder, ()) if n.name == name]
        if nodes:
            self._touch(holder)
            self.contents[holder] = [n for n in self.contents[holder] if n.name != name]
            return nodes
        if name in self.sources.get(holder, ()):
            return [self.portion(name)]
        return []

    def put_contents(self, holder: str, nodes: list) -> None:
        """Put content nodes into `holder`."""
        self._touch(holder)
        for n in nodes:
            n.arrived = self.step
        self.contents.setdefault(holder, []).extend(nodes)
        self.known_contents.update(n.name for n in nodes)
