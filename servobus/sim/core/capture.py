"""The virtual drives' 4 kHz sample trace: what ``AsyncAxis.trace_buffer()`` reads on ``sim://``.

A real drive's capture buffer records its servo loop on the drive's own clock; a virtual
drive does the same: while someone reads its trace, :class:`Recorder` observes every control
period (the core's ``period_observer``) and keeps position, position error, speed,
current and status (servobus.axis.capture). Nobody reading for :data:`IDLE_STOP_S` stops
the recording, so an unwatched drive runs its periods in one batch again.

``sim://`` opens drives through each protocol's own front end; :func:`collecting` notes
every virtual drive created while it is active (each family's drive calls
:func:`note_created` as it is built), so ``servobus.sim.schemes`` gives each opened axis a
:class:`SimCapture` without knowing the protocol or the family.

What is recorded is a :class:`Traced`: a family's view of a clocked core (the DMM drive as it
is, :class:`servobus.sim.dmm.trace.DriveTrace`; a YZ-AIM motor with its own address, counts,
offset and alarm). A front built on a core that was noted already replaces it
(:func:`note_front`). The host asks by the id it talks to, so several YZ-AIM motors on one
bus (whose cores all have id 0) each give their own trace.

Time: a drive's simulated time runs at wall-clock rate from a fixed offset
(servobus.sim.wall_clock); the offset is ``monotonic() - drive.time`` at the first read of the
drive and stays fixed, so sample times only ever grow (the drive lags the wall clock by at
most one clock tick, 4 ms: samples may be stamped up to that much late).
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, Protocol

from servobus.axis.capture import SIGNALS, Capture
from servobus.errors import ArgumentRangeError
from servobus.sim.core.constants import CONTROL_HZ

#: Samples kept between reads (2 s at 4 kHz); older ones are dropped and counted as lost.
CAPACITY = 2 * CONTROL_HZ
#: Recording stops when nobody has read the trace for this long (simulated seconds); what it
#: recorded until then is still handed out by the next read.
IDLE_STOP_S = 2.0


class Clocked(Protocol):
    """A simulated core that runs control periods (the DMM drive, the protocol-free Motor)."""

    time: float
    period_observer: Callable[[Any], None] | None

    @property
    def periods(self) -> int: ...


class Readouts(Protocol):
    """A core's readouts each period, as a trace and a step record take them (the DMM
    drive, the protocol-free Motor)."""

    @property
    def position_error(self) -> float: ...

    @property
    def speed_rpm(self) -> float: ...

    @property
    def current_a(self) -> float: ...


class Traced(Protocol):
    """What a trace records every control period of its core :attr:`drive`."""

    @property
    def drive(self) -> Clocked: ...

    @property
    def trace_id(self) -> int:
        """The id the host addresses it by."""

    @property
    def counts_per_rev(self) -> int: ...

    def trace_sample(self) -> tuple[float, float, float, float, int]:
        """Position, position error (counts), speed (rpm), current (A), status bits."""


_created: ContextVar[list[Traced] | None] = ContextVar("servobus_sim_created", default=None)


@contextmanager
def collecting() -> Iterator[list[Traced]]:
    """Every virtual drive (or front, :func:`note_front`) created inside the block (same task
    context) lands in the list."""
    made: list[Traced] = []
    token = _created.set(made)
    try:
        yield made
    finally:
        _created.reset(token)


def note_created(traced: Traced) -> None:
    """A virtual drive was built: what the host sees of it is ``traced``."""
    made = _created.get()
    if made is not None:
        made.append(traced)


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

    def __call__(self, drive: Clocked) -> None:
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


class SimCapture:
    """The CaptureSource of an in-process virtual line or bus (servobus.axis.capture)."""

    def __init__(self, traced: Sequence[Traced]) -> None:
        self.traced: list[Traced] = list(traced)
        self._recorders: dict[int, Recorder] = {}  # id(drive) -> recorder
        self._offset: dict[int, float] = {}  # id(drive) -> monotonic - simulated time

    @property
    def drives(self) -> list[Clocked]:
        """The cores recorded (a family's own view of them: ``traced``)."""
        return [t.drive for t in self.traced]

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
