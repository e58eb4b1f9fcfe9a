"""The kept gains of a tuning run, on disk while it runs (docs/tuning.md, "A run that is
killed").

A run writes gains under test to the drive (on DMM into EEPROM, so they outlive a power
cycle). Its abort paths write the kept gains back, but a process that is killed (SIGKILL, a
crash, the host losing power) cannot. So before its first gain write a run records the kept
gains in a file of the user's state folder (``$XDG_STATE_HOME/servobus/tune``, else
``~/.local/state/servobus/tune``), one file per drive (its link URL and drive id), and
removes it once the drive holds what the run meant to leave: the tuned gains, or the kept
ones written back. Decisions:

* a record whose process is gone is an interrupted run: the next run on that drive is
  refused (:class:`~servobus.errors.TuningInterrupted`, nothing moved or written) until
  ``servobus tune --restore`` (``restore_gains``) writes the kept gains back, which removes
  it. Tuning from the gains a killed run left would keep those as "the kept gains";
* a record whose process lives (this host, same process start) is another run on that
  drive: :class:`~servobus.errors.OwnerError`; it is created exclusively, so two processes
  never both start tuning one drive;
* a record from another host (a shared home folder) cannot be checked: it counts as
  alive for a new run, while ``--restore`` takes it (the user says that run is gone);
* in-process virtual drives (``sim://``) die with their process: nothing is recorded.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from servobus.errors import OwnerError, ServobusError, TuningInterrupted

FORMAT = 1


def folder() -> Path:
    """Where the records live: the user's own state folder."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "servobus" / "tune"


def _process_start(pid: int) -> str | None:
    """The kernel's start time of ``pid`` (Linux ``/proc``; None elsewhere): a pid reused by
    another process after a kill is not taken for the run."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[-1].split()[19]  # field 22, after the command's name


def _alive(pid: int, started: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    now = _process_start(pid)
    return started is None or now is None or now == started


@dataclass
class Record:
    """The record of one drive's run: ``drive`` names the drive (link URL and id), ``axis``
    the axis as the user named it."""

    drive: str
    axis: str
    path: Path
    ours: bool = False  # this process wrote it (and removes it)

    def read(self) -> dict[str, object] | None:
        """What the file holds, or None without one (an unreadable file: the error)."""
        try:
            text = self.path.read_text()
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise ServobusError(f"{self.axis}: cannot read the tuning record {self.path}: "
                                f"{exc}") from exc
        try:
            doc = json.loads(text)
            gains = doc["gains"]
            if not isinstance(gains, dict) or not all(
                    isinstance(k, str) and type(v) is int for k, v in gains.items()):
                raise ValueError("gains")
        except (ValueError, KeyError, TypeError) as exc:
            raise ServobusError(f"{self.axis}: the tuning record {self.path} is damaged "
                                f"({exc}); it is left as it is: read the kept gains from it "
                                "or delete it") from None
        return dict(doc)

    def _who(self, doc: Mapping[str, object]) -> str:
        return f"process {doc.get('pid')} on {doc.get('host')}, started {doc.get('time')}"

    def _lives(self, doc: Mapping[str, object]) -> bool:
        pid = doc.get("pid")
        if doc.get("host") != socket.gethostname():
            return True
        started = doc.get("started")
        return isinstance(pid, int) and _alive(pid, started if isinstance(started, str)
                                               else None)

    def check_free(self) -> None:
        """Before a run: OwnerError while another process tunes the drive,
        TuningInterrupted when a killed run left its gains."""
        doc = self.read()
        if doc is None:
            return
        if self._lives(doc):
            raise OwnerError(f"{self.axis} is being tuned by {self._who(doc)} (the record "
                             f"{self.path}); one run at a time", owner=f"pid {doc.get('pid')}")
        raise TuningInterrupted(
            f"{self.axis}: a tuning run ({self._who(doc)}) ended without writing its kept "
            f"gains back; the drive may still hold gains under test. `servobus tune "
            f"--restore` writes the kept gains {doc['gains']} back (they are in {self.path}); "
            "nothing was moved or written", path=self.path)

    def write(self, gains: Mapping[str, int]) -> None:
        """The kept gains, before the run's first gain write; created exclusively."""
        doc = {"format": FORMAT, "drive": self.drive, "axis": self.axis,
               "pid": os.getpid(), "started": _process_start(os.getpid()),
               "host": socket.gethostname(),
               "time": time.strftime("%Y-%m-%d %H:%M:%S"), "gains": dict(gains)}
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            raise OwnerError(f"{self.axis}: another run recorded its kept gains in "
                             f"{self.path} first; one run at a time") from None
        except OSError as exc:
            raise ServobusError(f"{self.axis}: cannot record the kept gains in "
                                f"{self.path} ({exc}): not tuned, nothing was written "
                                "(XDG_STATE_HOME chooses the folder)") from exc
        self.ours = True
        with os.fdopen(fd, "w") as out:
            json.dump(doc, out, indent=1)
            out.flush()
            os.fsync(out.fileno())

    def remove(self) -> None:
        """The run is over and the drive holds what it meant to leave (ours only)."""
        if self.ours:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
            self.ours = False

    def take(self) -> dict[str, int]:
        """For ``--restore``: the kept gains of an ended run (OwnerError while its process
        lives on this host; ServobusError without a record). Remove it with :meth:`drop`
        once they are back."""
        doc = self.read()
        if doc is None:
            raise ServobusError(f"{self.axis}: no interrupted tuning run is recorded "
                                f"(nothing in {self.path}): nothing to restore")
        if doc.get("host") == socket.gethostname() and self._lives(doc):
            raise OwnerError(f"{self.axis} is being tuned by {self._who(doc)}: stop that "
                             "run (it writes the kept gains back itself)",
                             owner=f"pid {doc.get('pid')}")
        gains = doc["gains"]
        assert isinstance(gains, dict)
        return {str(k): int(v) for k, v in gains.items()}

    def drop(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()


def record_for(url: str, drive_id: int, axis: str) -> Record | None:
    """The record of the drive at ``url`` with ``drive_id``; None for an in-process
    virtual drive (it dies with its process)."""
    if url.strip().lower().startswith("sim:"):
        return None
    drive = f"{url} id {drive_id}"
    name = hashlib.sha256(drive.encode()).hexdigest()[:16]
    return Record(drive, axis, folder() / f"{name}.json")
