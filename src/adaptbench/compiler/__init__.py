"""The spec compiler: YAML specs -> diagnostics and one immutable `CompiledDomain`.

    domain = load_domain()                           # the paper's spec (adaptbench.paper); cached by content hash
    domain, diagnostics = compile_spec(["spec"])     # every problem in one run
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sys
from dataclasses import astuple
from pathlib import Path

from .diagnostics import Diagnostic, SpecError
from .loader import spec_files
from .model import CompiledDomain

# The passes (build, checks, lint, sanity: lark and jsonschema) are imported inside compile_spec, so that a
# command that finds the domain in the cache starts in a few tens of milliseconds.

__all__ = ["CompiledDomain", "Diagnostic", "SpecError", "compile_cached", "compile_spec", "load_domain",
           "spec_hash"]

COMPILER_VERSION = "6"  # bump when the compiled form or its cache format changes


def _display(path: Path) -> str:
    try:
        return os.path.relpath(path)
    except ValueError:  # pragma: no cover - other drive on Windows
        return str(path)


def spec_hash(spec_dirs) -> str:
    """A content hash of every spec file (names and bytes) plus the compiler version."""
    h = hashlib.sha256(COMPILER_VERSION.encode())
    for kind, path in spec_files([Path(d) for d in spec_dirs]):
        try:
            data = path.read_bytes()
        except OSError as exc:  # compile_spec reports it; the hash only has to differ
            data = f"<unreadable: {exc}>".encode()
        h.update(kind.encode() + b"\0" + path.name.encode() + b"\0" + data + b"\0")
    return h.hexdigest()[:16]


def compile_spec(spec_dirs) -> tuple[CompiledDomain | None, list[Diagnostic]]:
    """Compile spec directories; return the domain (None if any error) and all diagnostics."""
    from .build import Draft
    from .checks import check_all
    from .lint import lint
    from .sanity import check_location_cycles, check_templates

    dirs = [Path(d) for d in spec_dirs]
    draft = Draft()
    _read_all(draft, _files(draft, dirs))
    if not check_location_cycles(draft) or draft.engine is None:  # later passes walk holder chains and
        return None, sorted(draft.diags)                             # name the engine's words
    check_all(draft)
    check_templates(draft)
    if any(d.severity == "error" for d in draft.diags):
        return None, sorted(draft.diags)
    domain = _freeze(draft, spec_hash(dirs))
    draft.diags.extend(lint(domain, draft.where))
    if any(d.severity == "error" for d in draft.diags):
        return None, sorted(draft.diags)
    return domain, sorted(draft.diags)


def _files(draft, dirs: list) -> list:
    """The spec files of the directories; S003/S004 for a missing or empty one, D501 with no engine.yaml."""
    for d in dirs:
        if not d.is_dir():
            draft.diags.append(Diagnostic(str(d), 1, 1, "S003", "spec directory not found"))
        elif not spec_files([d]):
            draft.diags.append(Diagnostic(str(d), 1, 1, "S004", "no spec files here (expected objects/, actions/, "
                                          "tasks/ and personas/ holding *.yaml files)"))
    files = spec_files(dirs)
    if files and not draft.diags and not any(kind == "engine" for kind, _ in files):
        draft.diags.append(Diagnostic(_display(dirs[0] / "engine.yaml"), 1, 1, "D501",
                                      "missing spec/engine.yaml: the engine vocabulary (dining places, component "
                                      "kinds, states ...) must be declared (see docs/authoring.md)"))
    return files


def _read_all(draft, files: list) -> None:
    """Load, schema-check and add every file to the draft."""
    from .build import ADDERS
    from .loader import load_file, validate_schema

    for kind, path in files:
        doc, diags = load_file(path, _display(path))
        draft.diags.extend(diags)
        schema_diags = validate_schema(doc, kind) if doc is not None else []
        draft.diags.extend(schema_diags)
        if doc is not None and not schema_diags:
            ADDERS[kind](draft, doc)
        elif kind == "persona":  # a persona that did not load is still not "unknown" to the splits
            draft.broken.add(path.stem)


def _unique(items):
    seen, out = set(), []
    for x in items:
        if x.id not in seen:
            seen.add(x.id)
            out.append(x)
    return tuple(out)


def _freeze(draft, digest: str) -> CompiledDomain:
    return CompiledDomain(
        spec_hash=digest,
        entities=_unique(draft.entities),
        substances=_unique(draft.substances),
        tags=tuple(sorted(draft.tags.items())),
        categories=tuple(sorted(draft.categories.items())),
        verb_groups=tuple((g, tuple(vs)) for g, vs in draft.verb_groups.items()),
        actions=_unique(draft.actions),
        components=_unique(draft.components),
        styles=_unique(draft.styles),
        tasks=_unique(draft.tasks),
        personas=tuple(sorted(_unique(draft.personas), key=lambda p: (p.number, p.id))),
        recipes=_unique(draft.recipes),
        planning=tuple(draft.planning),
        processes=tuple((g, tuple(vs)) for g, vs in draft.processes.items()),
        engine=draft.engine,
        splits=tuple(sorted(draft.splits, key=lambda s: s.id)),
    )


def cache_dir() -> Path:
    """Where compiled domains are cached ($ADAPT_CACHE, else $XDG_CACHE_HOME/adaptbench)."""
    env = os.environ.get("ADAPT_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "adaptbench"


def load_domain(spec_dir=None, use_cache: bool = True) -> CompiledDomain:
    """The compiled domain for `spec_dir` (cached on disk by content hash); SpecError on errors. By
    default the paper's spec shipped with the package (`adaptbench.paper.default_spec`: $ADAPT_SPEC
    overrides).

    A cache entry that fails to load or whose checksum does not match is discarded and rebuilt,
    with a one-line warning naming the file."""
    if spec_dir is None:
        from ..paper import default_spec

        spec_dir = default_spec()
    dirs = [spec_dir] if isinstance(spec_dir, str | Path) else list(spec_dir)
    digest = spec_hash(dirs)
    path = cache_dir() / f"domain-{digest}.json"
    if use_cache and path.exists():
        domain = _read_cache(path, digest)
        if domain is not None:
            return domain
    domain, diags = compile_spec(dirs)
    if domain is None:
        raise SpecError(diags)
    if use_cache:
        _write_cache(path, domain)
    return domain


def compile_cached(spec_dirs) -> tuple[CompiledDomain | None, list[Diagnostic]]:
    """`compile_spec` through the cache: a spec compiled before (same files, same working directory, so the
    same paths in the diagnostics) is read back with its warnings instead of compiled again."""
    dirs = [Path(d) for d in spec_dirs]
    digest = spec_hash(dirs)
    where = "\0".join([digest, os.getcwd(), *map(str, dirs)])
    dpath = cache_dir() / f"domain-{digest}.json"
    wpath = cache_dir() / f"diags-{hashlib.sha256(where.encode()).hexdigest()[:16]}.json"
    if dpath.exists() and wpath.exists():
        domain, diags = _read_cache(dpath, digest), _read_diags(wpath)
        if domain is not None and diags is not None:
            return domain, diags
    domain, diags = compile_spec(dirs)
    if domain is not None:
        _write_cache(dpath, domain)
        _write_bytes(wpath, json.dumps([list(astuple(d)) for d in diags]).encode())
    return domain, diags


def _read_diags(path: Path) -> list[Diagnostic] | None:
    try:
        return [Diagnostic(*row) for row in json.loads(path.read_text())]
    except (OSError, ValueError, TypeError):
        return None


_MAGIC = "adaptbench-domain-cache"


def _read_cache(path: Path, digest: str) -> CompiledDomain | None:
    try:
        head, _, body = path.read_bytes().partition(b"\n")
        magic, _, checksum = head.decode("ascii").partition(" ")
        if magic != _MAGIC:
            raise ValueError("not a cache file of this version")
        if hashlib.sha256(body).hexdigest() != checksum:
            raise ValueError("checksum mismatch")
        domain = CompiledDomain.from_json(body.decode("utf-8"))
        if domain.spec_hash != digest:
            raise ValueError("entry of another spec")
        return domain
    except Exception as exc:  # noqa: BLE001 - any broken entry is rebuilt, never fatal
        print(f"adapt: warning: discarded broken cache file {path} ({type(exc).__name__}: {exc}); rebuilding",
              file=sys.stderr)
        with contextlib.suppress(OSError):
            path.unlink()
        return None


def _write_cache(path: Path, domain: CompiledDomain) -> None:
    body = domain.to_json().encode("utf-8")
    _write_bytes(path, f"{_MAGIC} {hashlib.sha256(body).hexdigest()}\n".encode() + body)


def _write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")  # one per writer: concurrent runs never interleave
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(data)
        tmp.replace(path)
    except OSError:  # a read-only or full cache is not an error
        with contextlib.suppress(OSError):
            tmp.unlink()
