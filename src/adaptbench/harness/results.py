"""Results files that cannot be lost or doubled: one JSON line per episode, append-only.

    with ResultsFile.open(path, spec_hash) as store:   # exclusive lock; a torn tail is cut off
        if job_key not in store.done:
            store.append(record)                       # written once, fsync'd at a steady cadence

- The file is only ever appended to. A line torn by a kill or a full disk is removed by truncating the
  file in place to the end of the last complete line (one `ftruncate`; a kill during it leaves either
  the old or the new length, never an empty file).
- A second writer on the same file is refused (`fcntl.flock`, held for the whole run).
- An episode key (agent configuration, spec hash, persona, task, seed) is written at most once.
- A file the run created is removed again if the run ends before its first record (nothing half-written).
- A full disk (ENOSPC, EFBIG) truncates the partial line away and raises `DiskFull`: the file stays
  resumable.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import time
from pathlib import Path

from ..errors import AdaptError
from ..runtime.env import MAX_STEPS as DEFAULT_BUDGET

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no locking
    fcntl = None

FSYNC_SECONDS = 1.0  # at most this much finished work is exposed to a power cut
FSYNC_RECORDS = 64


class ResultsError(AdaptError):
    """A results file cannot be used (bad path, locked by another run); the message says why."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message, code=code)


class DiskFull(ResultsError):
    """The disk filled up while appending; everything before the failed record is intact."""


def agent_config(record: dict) -> dict:
    """The agent configuration of a record (records written before it was stored: scripted, offline user;
    before the step budget was recorded: the default budget, 50, which they ran at)."""
    config = record.get("agent_config") or {"agent": record.get("agent"), "user": "offline"}
    return config if "max_steps" in config else {**config, "max_steps": DEFAULT_BUDGET}


def episode_key(record: dict) -> tuple:
    """Identity of an episode: (agent configuration, spec hash, persona, task, seed)."""
    config = json.dumps(agent_config(record), sort_keys=True)
    return (config, record.get("spec_hash"), record.get("persona"), record.get("task"), record.get("seed"))


def _check_path(path: Path) -> None:
    if path.is_dir():
        raise ResultsError(f"--out {path} is a directory; give a file such as {path / 'results.jsonl'}", 2)
    if path.exists() and not path.is_file():
        raise ResultsError(f"--out {path} is not a regular file", 2)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise ResultsError(f"--out {path}: a parent of it is a file, not a directory", 2) from None
    except OSError as exc:
        raise ResultsError(f"--out {path}: cannot create its directory ({exc.strerror})", 2) from None


def _open_fd(path: Path) -> int:
    try:
        return os.open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND, 0o644)
    except OSError as exc:
        raise ResultsError(f"--out {path}: cannot open for writing ({exc.strerror})", 2) from None


def _lock(fd: int, path: Path) -> None:
    if fcntl is None:  # pragma: no cover
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise ResultsError(f"{path} is being written by another run (it holds the file's lock); "
                           f"wait for it to finish or choose another --out") from None


def repair_tail(fd: int) -> int:
    """Truncate a torn last line in place (never rewriting the file); return the bytes removed."""
    size = os.fstat(fd).st_size
    if size == 0:
        return 0
    end, chunk = size, 1 << 16
    while end > 0:  # scan backwards for the last newline
        start = max(0, end - chunk)
        data = os.pread(fd, end - start, start)
        if start + len(data) == size and data.endswith(b"\n"):
            return 0
        i = data.rfind(b"\n")
        if i >= 0:
            keep = start + i + 1
            break
        end = start
    else:
        keep = 0
    os.ftruncate(fd, keep)
    os.fsync(fd)
    return size - keep


def iter_lines(path: Path):
    """(line number, bytes) of every complete line of a file."""
    with open(path, "rb") as f:
        for n, line in enumerate(f, 1):
            if line.endswith(b"\n"):
                yield n, line


def parse_line(line: bytes):
    """The record on one line, or the reason it is not one."""
    try:
        rec = json.loads(line.decode("utf-8"))
    except UnicodeDecodeError:
        return None, "not UTF-8"
    except json.JSONDecodeError:
        return None, "not JSON"
    if not isinstance(rec, dict) or not {"agent", "persona", "task", "seed"} <= set(rec):
        return None, "not an episode record"
    return rec, None


class ResultsFile:
    """An exclusively locked, append-only results file (use `ResultsFile.open`)."""

    def __init__(self, path: Path, fd: int, repaired: int, created: bool = False):
        self.path, self.fd, self.repaired = path, fd, repaired
        self.created, self.appended = created, 0  # a file this run created is removed if nothing was appended
        self.done: set = set()
        self.skipped = 0  # lines that are not records
        self._unsynced, self._last_sync = 0, time.monotonic()

    @classmethod
    def open(cls, path, spec_hash: str | None = None) -> ResultsFile:
        """Lock `path` (creating it), cut a torn tail, and read the episode keys already there."""
        path = Path(path)
        _check_path(path)
        created = not path.exists()
        fd = _open_fd(path)
        _lock(fd, path)
        try:
            store = cls(path, fd, repair_tail(fd), created)
            store._read(spec_hash)
        except BaseException:
            os.close(fd)
            raise
        return store

    def _read(self, spec_hash) -> None:
        for _, line in iter_lines(self.path):
            rec, _why = parse_line(line)
            if rec is None:
                self.skipped += 1
            elif spec_hash is None or rec.get("spec_hash") == spec_hash:
                self.done.add(episode_key(rec))

    def append(self, record: dict) -> bool:
        """Write one record unless its episode is already in the file; False if it was."""
        key = episode_key(record)
        if key in self.done:
            return False
        data = (json.dumps(record) + "\n").encode()
        before = os.fstat(self.fd).st_size
        try:
            _write_all(self.fd, data)
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
                self._undo(before)
                raise DiskFull(f"disk full writing {self.path} ({exc.strerror}); "
                               f"every finished episode before it is kept") from None
            raise ResultsError(f"cannot write {self.path} ({exc.strerror})") from None
        self.done.add(key)
        self.appended += 1
        self._unsynced += 1
        if self._unsynced >= FSYNC_RECORDS or time.monotonic() - self._last_sync >= FSYNC_SECONDS:
            self.sync()
        return True

    def _undo(self, size: int) -> None:
        with contextlib.suppress(OSError):  # the next open repairs the tail anyway
            os.ftruncate(self.fd, size)

    def sync(self) -> None:
        """Flush appended records to disk."""
        if self._unsynced:
            with contextlib.suppress(OSError):
                os.fsync(self.fd)
        self._unsynced, self._last_sync = 0, time.monotonic()

    def close(self) -> None:
        """Sync, unlock and close; a file this run created and wrote nothing to is removed (a run that
        failed before its first episode leaves no empty results file behind)."""
        if self.fd >= 0:
            if self.created and not self.appended and os.fstat(self.fd).st_size == 0:
                with contextlib.suppress(OSError):
                    self.path.unlink()
            self.sync()
            os.close(self.fd)
            self.fd = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]
