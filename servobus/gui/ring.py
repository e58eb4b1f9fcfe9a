"""A bounded record of one axis's samples: times and one array per scope signal.

Samples arrive in time order (a drive's trace, or polls). Indices are absolute (they keep
counting as old samples are dropped), so a reader can resume where it left off. A signal
a sample does not have (a poll that did not read it) is NaN.
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_left
from collections.abc import Mapping, Sequence

from servobus.gui.signals import SIGNALS

NAN = math.nan


class SampleRing:
    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self.capacity = capacity
        self.base = 0  # absolute index of times[0]
        self.times: array[float] = array("d")
        self.data: dict[str, array[float]] = {name: array("d") for name in SIGNALS}

    # ------------------------------------------------------------- writing
    def append(self, t: float, values: Mapping[str, float]) -> None:
        """One sample at time ``t``; signals missing from ``values`` are NaN."""
        self.times.append(t)
        for name, column in self.data.items():
            column.append(values.get(name, NAN))
        self._trim()

    def extend(self, times: Sequence[float], values: Mapping[str, Sequence[float]]) -> None:
        """Several samples; each column of ``values`` has len(times) entries (or is absent)."""
        n = len(times)
        if n == 0:
            return
        self.times.extend(times)
        for name, column in self.data.items():
            given = values.get(name)
            if given is None:
                column.extend(array("d", [NAN]) * n)
            else:
                if len(given) != n:
                    raise ValueError(f"{name}: {len(given)} values for {n} times")
                column.extend(given)
        self._trim()

    def _trim(self) -> None:
        extra = len(self.times) - self.capacity
        if extra > self.capacity // 2:  # amortised: drop in blocks
            del self.times[:extra]
            for column in self.data.values():
                del column[:extra]
            self.base += extra

    def clear(self) -> None:
        self.base += len(self.times)
        del self.times[:]
        for column in self.data.values():
            del column[:]

    # ------------------------------------------------------------- reading
    @property
    def end(self) -> int:
        """Absolute index after the newest sample."""
        return self.base + len(self.times)

    def __len__(self) -> int:
        return len(self.times)

    @property
    def first_time(self) -> float | None:
        return self.times[0] if self.times else None

    @property
    def last_time(self) -> float | None:
        return self.times[-1] if self.times else None

    def index_at(self, t: float) -> int:
        """Absolute index of the first sample at or after ``t`` (``end`` if none)."""
        return self.base + bisect_left(self.times, t)

    def time(self, index: int) -> float:
        return self.times[index - self.base]

    def value(self, name: str, index: int) -> float:
        return self.data[name][index - self.base]

    def column(self, name: str, i0: int, i1: int) -> array[float]:
        """Values of ``name`` for absolute indices [i0, i1), clamped to what is kept."""
        lo = max(i0, self.base) - self.base
        hi = max(lo, min(i1, self.end) - self.base)
        return self.data[name][lo:hi]

    def time_slice(self, i0: int, i1: int) -> array[float]:
        lo = max(i0, self.base) - self.base
        hi = max(lo, min(i1, self.end) - self.base)
        return self.times[lo:hi]
