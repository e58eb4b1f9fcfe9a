"""Scope trigger: find a level crossing in a ring and hand out complete capture windows.

Modes (what the page offers): ``roll`` (free running, no trigger), ``auto`` (triggered
captures; the scope free-runs when none comes), ``normal`` (only triggered captures),
``single`` (one triggered capture, then hold until re-armed). The capture window is
[t - pre x window, t + (1 - pre) x window] around the trigger time t; the next trigger is
searched after the end of the window (the hold-off a scope has while it fills its record).

The trigger time is interpolated between the two samples around the crossing, so a
repetitive signal shows still even when the sample grid does not line up with it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

from servobus.gui.ring import SampleRing

MODES = ("roll", "auto", "normal", "single")


class Edge(Enum):
    RISING = "rising"
    FALLING = "falling"
    EITHER = "either"


def find_crossing(values: Sequence[float], level: float, edge: Edge,
                  start: int = 1) -> int | None:
    """First index ``i >= max(start, 1)`` where the signal crosses ``level``: rising means
    ``values[i-1] < level <= values[i]``, falling ``values[i-1] > level >= values[i]``."""
    rising = edge is not Edge.FALLING
    falling = edge is not Edge.RISING
    prev = values[max(start, 1) - 1] if len(values) else math.nan
    for i in range(max(start, 1), len(values)):
        v = values[i]
        if (rising and prev < level <= v) or (falling and prev > level >= v):
            return i
        prev = v
    return None


def crossing_time(t0: float, v0: float, t1: float, v1: float, level: float) -> float:
    """Time the straight line from (t0, v0) to (t1, v1) reaches ``level``."""
    if v1 == v0:
        return t1
    return t0 + (t1 - t0) * (level - v0) / (v1 - v0)


@dataclass(frozen=True)
class TriggerSettings:
    mode: str = "auto"
    edge: Edge = Edge.RISING
    level: float = 0.0
    pre: float = 0.1  # fraction of the window before the trigger, 0..1
    window_s: float = 1.0

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"trigger mode {self.mode!r}: one of {', '.join(MODES)}")
        if not 0.0 <= self.pre <= 1.0:
            raise ValueError(f"pre-trigger {self.pre!r} must be within 0..1")
        if not (self.window_s > 0 and math.isfinite(self.window_s)):
            raise ValueError(f"window {self.window_s!r} s must be > 0")
        if not math.isfinite(self.level):
            raise ValueError("trigger level must be finite")

    @property
    def post_s(self) -> float:
        return (1.0 - self.pre) * self.window_s

    @property
    def pre_s(self) -> float:
        return self.pre * self.window_s


class TriggerTracker:
    """Watches one signal of one ring; :meth:`poll` returns completed trigger times."""

    def __init__(self, settings: TriggerSettings, ring: SampleRing, signal: str) -> None:
        self.settings, self.ring, self.signal = settings, ring, signal
        self.search_from = ring.end  # only samples that arrive after arming
        self.pending: float | None = None
        self.done = False  # single mode: captured, holding

    def rearm(self) -> None:
        self.search_from = self.ring.end
        self.pending = None
        self.done = False

    def poll(self) -> float | None:
        """The time of a trigger whose whole window is now in the ring, else None."""
        if self.done or self.settings.mode == "roll":
            return None
        ring = self.ring
        if self.pending is None:
            start = max(self.search_from, ring.base + 1)
            if start < ring.end:
                column = ring.data[self.signal]
                i = find_crossing(column, self.settings.level, self.settings.edge,
                                  start - ring.base)
                if i is None:
                    self.search_from = ring.end
                else:
                    j = ring.base + i
                    self.pending = crossing_time(ring.time(j - 1), ring.value(self.signal, j - 1),
                                                 ring.time(j), ring.value(self.signal, j),
                                                 self.settings.level)
                    self.search_from = j + 1
        last = ring.last_time
        if self.pending is None or last is None or last < self.pending + self.settings.post_s:
            return None
        t, self.pending = self.pending, None
        self.search_from = max(self.search_from, ring.index_at(t + self.settings.post_s))
        if self.settings.mode == "single":
            self.done = True
        return t
