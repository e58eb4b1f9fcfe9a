"""The state file of the virtual drives: their EEPROM records, kept across restarts.

Every family's virtual drive (the DMM drives, :mod:`servobus.sim.dmm.eeprom`; the YZ-AIM
motors, :mod:`servobus.sim.yzaim.store`) keeps its EEPROM in one machinery: a
:class:`StateKind` names what a file holds and checks one record; a file is opened as one
kind per process (a DMM and a YZ-AIM simulator cannot share one file). Decisions:

* It is checked whole at start-up and the simulator refuses to start on anything it cannot
  serve faithfully, with one line naming the file and the problem (:class:`StateFileError`);
  the file is never rewritten then. What a valid record is, is the kind's.
* A missing file is created (``{}``) at start-up, which also proves the directory writable.
* One process at a time: the file is locked (``fcntl.flock``, exclusive, non-blocking; not
  on Windows); a second simulator on the same file refuses to start. Within one process,
  every store on the same path shares one :class:`StateFile`.
* Writes are atomic: the whole file goes to ``FILE.tmp`` (locked before it is renamed, so
  the lock moves with the content) and is renamed over ``FILE``. A ``FILE.tmp`` left by a
  killed simulator is removed at start-up, once the lock is held. No fsync: the file
  survives the simulator being killed, not a power cut of the host.
* A write that fails later (disk full, directory removed) logs one line; the drive keeps
  running on the values in RAM and the next write tries again.
* A file nested too deeply to be a state file (JSON parsing would exhaust the recursion limit)
  is refused with one line like any other invalid file.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from servobus.errors import ServobusError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: the state file is not locked there
    fcntl = None  # type: ignore[assignment]

MAX_STATE_BYTES = 1 << 20  # 64 records are a few KiB; anything this large is not a state file
_LOCK_ATTEMPTS = 20  # the file may be replaced between open and lock by its owner's write

logger = logging.getLogger("servobus.sim")


class StateFileError(ServobusError):
    """The ``--state`` file cannot be used; nothing was written to it."""


RecordCheck = Callable[[str, object], dict[str, Any]]


@dataclass(frozen=True)
class StateKind:
    """What a state file holds: ``holds`` names its records in messages, ``check`` checks one
    record (key, value) and returns it normalised, or raises ValueError naming the problem."""

    holds: str
    check: RecordCheck


class StateFile:
    """One validated, locked state file shared by the stores of one process."""

    @classmethod
    def shared(cls, path: str | Path, kind: StateKind) -> StateFile:
        """The process's one StateFile for ``path`` (opened, checked and locked on first use)."""
        key = os.path.realpath(path)
        found = _OPEN.get(key)
        if found is None:
            found = cls(Path(path), kind)
            _OPEN[key] = found
        elif found.kind is not kind:
            found._fail(f"is in use by this process for {found.kind.holds}",
                        f"use another file for {kind.holds}")
        return found

    def __init__(self, path: Path, kind: StateKind) -> None:
        self.path = path
        self.kind = kind
        self.tmp = path.with_name(path.name + ".tmp")
        self.records: dict[str, dict[str, Any]] = {}
        self._fd = [-1]  # the locked descriptor, in a box the finalizer can see
        self._failing = False
        self._check_location()
        self._fd[0], raw = self._lock()
        weakref.finalize(self, _close_box, self._fd)
        try:
            self.records = parse_state(raw, str(path), self.kind)
            self._check_writable()
        except StateFileError:
            _close_box(self._fd)
            raise

    # ---------------------------------------------------------------- start-up
    def _fail(self, problem: str, hint: str = "fix or remove it; it was not changed"
              ) -> NoReturn:
        raise StateFileError(f"state file {self.path}: {problem} - {hint}")

    def _check_location(self) -> None:
        parent = self.path.parent
        if self.path.is_dir():
            self._fail("is a directory", "name a file inside it")
        if not parent.exists():
            self._fail(f"its directory {parent} does not exist", "create it first")
        if not parent.is_dir():
            self._fail(f"{parent} is not a directory", "name a file in a directory")
        if self.path.exists() and not os.access(self.path, os.R_OK):
            self._fail("cannot be read (permission denied)", "check its permissions")

    def _check_writable(self) -> None:
        """With the lock held: drop a stale FILE.tmp, prove the directory takes a new one."""
        with contextlib.suppress(FileNotFoundError):
            self.tmp.unlink()  # left by a simulator killed mid-write
        try:
            probe = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as exc:
            self._not_writable(exc)
        os.close(probe)
        os.unlink(self.tmp)
        if not os.access(self.path, os.W_OK):
            self._fail("is read-only", "make it writable or use a copy")

    def _not_writable(self, exc: OSError) -> NoReturn:
        reason = os.strerror(exc.errno) if exc.errno else str(exc)
        self._fail(f"its directory {self.path.parent} is not writable ({reason})",
                   "choose a writable place")

    def _lock(self) -> tuple[int, bytes]:
        """Open and lock the file that ``path`` names (creating ``{}`` if missing)."""
        for _ in range(_LOCK_ATTEMPTS):
            try:
                fd = os.open(self.path, os.O_RDONLY)
            except FileNotFoundError:
                try:
                    self._create()
                except OSError as exc:
                    self._not_writable(exc)
                continue  # lock the file now there (ours, or one created meanwhile)
            try:
                _lock_fd(fd)
            except BlockingIOError:
                os.close(fd)
                self._fail("is in use by another simulator process",
                           "stop that one or use another file")
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # replaced between open and lock: lock the current one
                os.close(fd)
                continue
            return fd, _read_all(fd)
        self._fail("keeps changing while it is opened", "stop the other writer")

    def _create(self) -> None:
        """Create ``path`` holding ``{}`` without ever clobbering a file that appears.

        Written under a name of this process's own, then hard-linked: the file appears
        complete or not at all.
        """
        fresh = self.path.with_name(f".{self.path.name}.{os.getpid()}.new")
        fd = os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            os.write(fd, b"{}\n")
        finally:
            os.close(fd)
        try:
            os.link(fresh, self.path)
        except FileExistsError:
            pass  # someone else's file appeared: it is locked and checked like any other
        finally:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(fresh)

    # ---------------------------------------------------------------- writing
    def save(self, key: str, record: dict[str, Any]) -> None:
        self.records[key] = record
        data = (json.dumps(self.records, indent=1, sort_keys=True) + "\n").encode()
        try:
            fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                _lock_fd(fd)  # the lock moves with the data
                view = memoryview(data)
                while view:
                    view = view[os.write(fd, view):]
                os.replace(self.tmp, self.path)
            except BaseException:
                os.close(fd)
                with contextlib.suppress(OSError):
                    os.unlink(self.tmp)
                raise
        except OSError as exc:
            if not self._failing:
                self._failing = True
                logger.warning("state file %s: cannot save (%s) - EEPROM changes are kept in "
                               "memory only until a save succeeds", self.path,
                               os.strerror(exc.errno or 0) if exc.errno else exc)
            return
        self._failing = False
        old, self._fd[0] = self._fd[0], fd
        if old >= 0:
            os.close(old)  # the replaced file's lock goes with it


_OPEN: weakref.WeakValueDictionary[str, StateFile] = weakref.WeakValueDictionary()


def _lock_fd(fd: int) -> None:
    """Exclusive, non-blocking flock; BlockingIOError when another process holds it."""
    if fcntl is not None:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)


def _close_box(box: list[int]) -> None:
    """Close the locked descriptor (releases the lock); also the StateFile's finalizer."""
    fd, box[0] = box[0], -1
    if fd >= 0:
        os.close(fd)


def _read_all(fd: int) -> bytes:
    chunks = []
    total = 0
    while chunk := os.read(fd, 65536):
        chunks.append(chunk)
        total += len(chunk)
        if total > MAX_STATE_BYTES:
            break
    return b"".join(chunks)


# ---------------------------------------------------------------- validation
def parse_state(raw: bytes, name: str, kind: StateKind) -> dict[str, dict[str, Any]]:
    """The records of a state file's bytes; StateFileError (one line) if anything is off."""

    def fail(problem: str) -> StateFileError:
        return StateFileError(f"state file {name}: {problem} - fix or remove it; it was not "
                              "changed")

    if not raw.strip():
        raise fail("is empty")
    if len(raw) > MAX_STATE_BYTES:
        raise fail(f"is larger than {MAX_STATE_BYTES // 1024} KiB: not a state file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise fail("is not text (binary data?)") from None
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except ValueError as exc:
        msg = exc.msg if isinstance(exc, json.JSONDecodeError) else str(exc)
        where = (f" at line {exc.lineno} column {exc.colno}"
                 if isinstance(exc, json.JSONDecodeError) else "")
        raise fail(f"is not valid JSON ({msg}{where}; truncated?)") from None
    except RecursionError:
        raise fail("nests too deeply to be a state file") from None
    if not isinstance(doc, dict):
        raise fail(f"holds {describe(doc)}, expected an object of {kind.holds}")
    records: dict[str, dict[str, Any]] = {}
    for key, rec in doc.items():
        try:
            records[key] = kind.check(key, rec)
        except ValueError as exc:
            raise fail(f"record {key!r}: {exc}") from None
        except RecursionError:
            raise fail(f"record {key!r} nests too deeply to be a state file") from None
    return records


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def describe(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, list):
        return "a list"
    return f"a {type(value).__name__}"


def checked_int(value: object, what: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{what} must be an integer, got {json.dumps(value)[:40]}")
    if not low <= value <= high:
        raise ValueError(f"{what} {value} is outside {low}..{high}")
    return value


class RecordStore:
    """One drive's record in a shared state file (none without ``path``), under ``key``.

    A family's store sets its defaults, then calls this ``__init__``, which takes the stored
    record back through :meth:`_restore` when there is one; :meth:`save` writes what
    :meth:`_record` says the record holds (servobus.sim.dmm.eeprom, servobus.sim.yzaim.store).
    """

    def __init__(self, path: str | Path | None, key: str, kind: StateKind) -> None:
        self.path = Path(path) if path is not None else None
        self.key = key
        self._file = StateFile.shared(self.path, kind) if self.path is not None else None
        rec = self._file.records.get(key) if self._file is not None else None
        if rec is not None:
            self._restore(rec)

    def _record(self) -> dict[str, Any]:
        raise NotImplementedError

    def _restore(self, rec: dict[str, Any]) -> None:
        raise NotImplementedError

    def save(self) -> None:
        if self._file is not None:
            self._file.save(self.key, self._record())
