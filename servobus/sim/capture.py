"""The virtual drives' 4 kHz sample trace: what ``AsyncAxis.trace_buffer()`` reads on ``sim://``.

A real drive's capture buffer records its servo loop on the drive's own clock; a virtual
drive does the same: while someone reads its trace, :class:`Recorder` observes every control
period (``VirtualDrive.period_observer``) and keeps position, position error, speed,
current and status (servobus.axis.capture). Nobody reading for :data:`IDLE_STOP_S` stops
the recording, so an unwatched drive runs its periods in one batch again.

``sim://`` opens drives through each protocol's own front end; :func:`collecting` notes
every VirtualDrive created while it is active (``VirtualDrive.__init__`` calls
:func:`note_created`), so ``servobus.sim.schemes`` gives each opened axis a
:class:`SimCapture` without knowing the protocol.

What is recorded is a :class:`Traced`: a DMM VirtualDrive as it is (:class:`DriveTrace`: its
id, its counts), or a motor of another family built on one (a YZ-AIM motor: its own address,
its own counts and offset, its own alarm), which replaces its core with :func:`note_front`.
The host asks by the id it talks to, so several YZ-AIM motors on one bus (whose cores all
have id 0) each give their own trace.

Time: a drive's simulated time runs at wall-clock rate from a fixed offset
(servobus.sim.realtime); the offset is ``monotonic() - drive.time`` at the first read of the
drive and stays fixed, so sample times only ever grow (the drive lags the wall clock by at
most one clock tick, 4 ms: samples may be stamped up to that much late).
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import TYPE_CHECKING, Protocol

from servobus.axis.capture import SIGNALS, Capture, status_bits
from servobus.errors import ArgumentRangeError
from servobus.families.base import motion_state
from servobus.families.dmm import units as U
from servobus.sim.core.constants import CONTROL_HZ

if TYPE_CHECKING:
    from servobus.sim.core.motor import Motor
    from servobus.sim.dmm.drive import VirtualDrive

#: Samples kept between reads (2 s at 4 kHz); older ones are dropped and counted as lost.
CAPACITY = 2 * CONTROL_HZ
#: Recording stops when nobody has read the trace for this long (simulated seconds); what it
#: recorded until then is still handed out by the next read.
IDLE_STOP_S = 2.0



class Traced(Protocol):
    """What a trace records every control period of its core :attr:`drive`."""

    @property
    def drive(self) -> VirtualDrive | Motor: ...

    @property
    def trace_id(self) -> int:
        """The id the host addresses it by."""

    @property
    def counts_per_rev(self) -> int: ...

    def trace_sample(self) -> tuple[float, float, float, float, int]:
        """Position, position error (counts), speed (rpm), current (A), status bits."""


class DriveTrace:
    """A DMM VirtualDrive as the host sees it: its own id and counts."""

    __slots__ = ("drive",)
    counts_per_rev = U.COUNTS_PER_REV

    def __init__(self, drive: VirtualDrive) -> None:
        self.drive = drive

    @property
    def trace_id(self) -> int:
        return self.drive.drive_id

    def trace_sample(self) -> tuple[float, float, float, float, int]:
        d = self.drive
        speed = d.speed_rpm
        enabled, busy, on_position, alarm = d.trace_flags()
        moving, in_position = motion_state(busy, on_position, speed)  # as AxisStatus has them
        return (d.position, d.position_error, speed, d.current_a,
                status_bits(enabled, moving, in_position, alarm))


_created: ContextVar[list[Traced] | None] = ContextVar("servobus_sim_created", default=None)


@contextmanager
def collecting() -> Iterator[list[Traced]]:
    """Every VirtualDrive (or front, :func:`note_front`) created inside the block (same task
    context) lands in the list."""
    made: list[Traced] = []
    token = _created.set(made)
    try:
        yield made
    finally:
        _created.reset(token)


def note_created(drive: VirtualDrive) -> None:
    made = _created.get()
    if made is not None:
        made.append(DriveTrace(drive))


def note_front(front: Traced) -> None:
    """``front`` (a motor built on ``front.drive``) is what the host sees of that drive."""
    made = _created.get()
    if made is not None:
        made[:] = [t for t in made if t.drive is not front.drive]
        made.append(front)


class Recorder:
    """One drive's trace while it is read: a per-period observer with bounded buffers."""

    def __init__(self, traced: Traced) -> None:
        drive = traced.drive
        self.drive = drive
        self._sample = traced.trace_sample
        self.first_period = drive.periods + 1  # period whose end the first sample shows
        self.lost = 0
        self.last_read = drive.periods
        self._pos: array[float] = array("d")
        self._err: array[float] = array("d")
        self._speed: array[float] = array("d")
        self._current: array[float] = array("d")
        self._status: array[float] = array("d")
        drive.period_observer = self

    @property
    def active(self) -> bool:
        return self.drive.period_observer is self

    def __call__(self, drive: VirtualDrive | Motor) -> None:
        if drive.periods - self.last_read > IDLE_STOP_S * CONTROL_HZ:
            drive.period_observer = None  # nobody reads: stop costing CPU
            return
        position, error, speed, current, status = self._sample()
        self._pos.append(position)
        self._err.append(error)
        self._speed.append(speed)
        self._current.append(current)
        self._status.append(status)
        if len(self._pos) >= 2 * CAPACITY:  # amortised: trim in blocks
            self._drop(len(self._pos) - CAPACITY)

    def _drop(self, n: int) -> None:
        for buf in (self._pos, self._err, self._speed, self._current, self._status):
            del buf[:n]
        self.first_period += n
        self.lost += n

    def take(self) -> tuple[int, dict[str, array[float]], int]:
        """(period index of the first sample, signals, samples lost) since the last take."""
        if len(self._pos) > CAPACITY:
            self._drop(len(self._pos) - CAPACITY)
        first, lost = self.first_period, self.lost
        signals = {"position": self._pos, "position_error": self._err,
                   "speed": self._speed, "current": self._current, "status": self._status}
        assert set(signals) == set(SIGNALS)
        n = len(self._pos)
        self._pos, self._err, self._speed = array("d"), array("d"), array("d")
        self._current, self._status = array("d"), array("d")
        self.first_period, self.lost = first + n, 0
        self.last_read = self.drive.periods
        return first, signals, lost


def _traced(item: VirtualDrive | Traced) -> Traced:
    from servobus.sim.dmm.drive import VirtualDrive  # drive imports this module

    return DriveTrace(item) if isinstance(item, VirtualDrive) else item


class SimCapture:
    """The CaptureSource of an in-process virtual line or bus (servobus.axis.capture)."""

    def __init__(self, drives: Sequence[VirtualDrive | Traced]) -> None:
        self.traced: list[Traced] = [_traced(d) for d in drives]
        self._recorders: dict[int, Recorder] = {}  # id(drive) -> recorder
        self._offset: dict[int, float] = {}  # id(drive) -> monotonic - simulated time

    @property
    def drives(self) -> list[VirtualDrive]:
        """The DMM virtual drives recorded (a YZ-AIM motor's core is no drive: left out)."""
        from servobus.sim.dmm.drive import VirtualDrive  # drive imports this module

        return [t.drive for t in self.traced if isinstance(t.drive, VirtualDrive)]

    def _find(self, drive_id: int) -> Traced:
        for traced in self.traced:
            if traced.trace_id == drive_id:
                return traced
        if len(self.traced) == 1:  # one drive on the line: whatever id it is asked by
            return self.traced[0]
        raise ArgumentRangeError(f"no virtual drive {drive_id} on this line")

    def read(self, drive_id: int) -> Capture:
        traced = self._find(drive_id)
        drive = traced.drive
        key = id(drive)
        offset = self._offset.setdefault(key, time.monotonic() - drive.time)
        rec = self._recorders.get(key)
        if rec is None:
            rec = self._recorders[key] = Recorder(traced)
        elif not rec.active:  # stopped unread: hand out what it kept, then record afresh
            self._recorders[key] = Recorder(traced)
        first, signals, lost = rec.take()
        return Capture(t0=offset + first / CONTROL_HZ, rate_hz=float(CONTROL_HZ),
                       counts_per_rev=traced.counts_per_rev, signals=signals, lost=lost)
