"""The scope's signals: one table (name, unit, label) shared by the server and the page.

A scope channel is one signal of one axis. ``position``/``position_error`` are counts of
the axis's family, ``speed`` rpm, ``current`` A (servobus.axis.capture); the status bits are
0/1 (servobus.axis.capture.STATUS_BITS). ``position_error`` exists only where the drive
keeps a trace (``trace_buffer``); a polled axis shows it as no data.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from servobus.axis.capture import STATUS_BITS


@dataclass(frozen=True)
class Signal:
    name: str
    unit: str
    label: str
    bit: int | None = None  # bit of the capture's ``status`` signal, for a status bit


SIGNALS: Mapping[str, Signal] = {s.name: s for s in (
    Signal("position", "counts", "position"),
    Signal("position_error", "counts", "position error"),
    Signal("speed", "rpm", "speed"),
    Signal("current", "A", "current"),
    *(Signal(bit, "bit", bit.replace("_", " "), i) for i, bit in enumerate(STATUS_BITS)),
)}
#: Signals a poll reads with one call each (the bits come from one status read).
POLLED_READS: Mapping[str, str] = {"position": "position", "speed": "speed",
                                   "current": "current"}
BIT_SIGNALS: tuple[str, ...] = tuple(n for n, s in SIGNALS.items() if s.bit is not None)


def expand_status(status: float) -> dict[str, float]:
    """A capture's ``status`` sample -> one 0/1 value per status-bit signal."""
    bits = int(status)
    return {name: float(bits >> SIGNALS[name].bit & 1)  # type: ignore[operator]
            for name in BIT_SIGNALS}
