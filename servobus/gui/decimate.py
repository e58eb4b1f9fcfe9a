"""Reduce samples to what a screen can show: min/max per pixel-wide time bucket.

Values travel as float32 (what a frame carries), times as float64.

The window [t_origin, t_origin + n x dt) is cut into ``n`` buckets of ``dt`` seconds. With
``pairs`` each bucket gives two points, its minimum and maximum in the order they occurred
(a spike one sample wide stays visible, a ramp stays a line); without, the last sample of
the bucket (for sparse data: about one sample per bucket). An empty bucket repeats the last
value before it (a sample-and-hold line, as a scope shows sparse data), NaN before the first.

:class:`RollingDecimator` keeps buckets on an absolute grid (bucket k = [k dt, (k+1) dt)), so
a rolling display reduces each sample once instead of the whole window every frame.
"""

from __future__ import annotations

import functools
import math
from array import array
from collections.abc import Sequence
from dataclasses import dataclass

from servobus.gui.ring import SampleRing

NAN = math.nan
#: Below this many samples per bucket a bucket shows one point (its last sample), not two.
PAIRS_FROM_SAMPLES_PER_BUCKET = 1.5


def use_pairs(window_s: float, rate_hz: float, buckets: int) -> bool:
    return window_s * rate_hz / max(1, buckets) > PAIRS_FROM_SAMPLES_PER_BUCKET


def bucket_count(window_s: float, rate_hz: float, width_px: int, minimum: int = 16) -> int:
    """Buckets for a window: one per pixel at most, about one per sample when data is sparse."""
    expected = int(window_s * rate_hz) if rate_hz > 0 else width_px
    return max(min(minimum, width_px), min(width_px, expected))


@dataclass
class Columns:
    """Per signal: the first and second point of each bucket (``b`` unused without pairs)."""

    a: dict[str, array[float]]
    b: dict[str, array[float]]


def reduce_buckets(ring: SampleRing, names: Sequence[str], t_origin: float, dt: float,
                   k0: int, k1: int, pairs: bool, last: dict[str, float]) -> Columns:
    """Buckets k0..k1-1 of the grid ``t_origin + k x dt``. ``last`` holds the value before
    bucket k0 per signal (forward fill) and is updated to the value after bucket k1-1."""
    out = Columns({n: array("f") for n in names}, {n: array("f") for n in names})
    base = ring.base
    lo = ring.index_at(t_origin + k0 * dt) - base
    for k in range(k0, k1):
        hi = ring.index_at(t_origin + (k + 1) * dt) - base
        for name in names:
            if hi > lo:
                seg = ring.data[name][lo:hi]
                if pairs:
                    mn, mx = min(seg), max(seg)
                    first, second = (mn, mx) if seg.index(mn) <= seg.index(mx) else (mx, mn)
                    out.a[name].append(first)
                    out.b[name].append(second)
                else:
                    out.a[name].append(seg[-1])
                last[name] = seg[-1]
            else:
                v = last.get(name, NAN)
                out.a[name].append(v)
                if pairs:
                    out.b[name].append(v)
        lo = hi
    return out


@dataclass
class Decimated:
    """What a frame carries: x (seconds from ``t_ref``) and one y array per signal."""

    x: array[float]
    ys: dict[str, array[float]]
    pairs: bool
    raw_count: int  # samples that fell into the window


@functools.lru_cache(maxsize=16)
def bucket_x(x_first: float, dt: float, n: int, pairs: bool) -> array[float]:
    """x of n buckets: their quarter and three-quarter points (pairs) or centres. Cached: a
    rolling display asks for the same x every frame (do not modify the result)."""
    if pairs:
        x = array("d", bytes(16 * n))
        x[0::2] = array("d", (x_first + (k + 0.25) * dt for k in range(n)))
        x[1::2] = array("d", (x_first + (k + 0.75) * dt for k in range(n)))
        return x
    return array("d", (x_first + (k + 0.5) * dt for k in range(n)))


def assemble(cols: Columns, names: Sequence[str], x_first: float, dt: float, n: int,
             pairs: bool) -> tuple[array[float], dict[str, array[float]]]:
    """Interleave a/b into the y arrays; x from :func:`bucket_x`."""
    x = bucket_x(x_first, dt, n, pairs)
    if not pairs:
        return x, {name: cols.a[name] for name in names}
    ys: dict[str, array[float]] = {}
    for name in names:
        y = array("f", bytes(8 * n))
        y[0::2] = cols.a[name]
        y[1::2] = cols.b[name]
        ys[name] = y
    return x, ys


def decimate_window(ring: SampleRing, names: Sequence[str], t_start: float, t_end: float,
                    buckets: int, pairs: bool, t_ref: float) -> Decimated:
    """One-shot reduction of [t_start, t_end) (a triggered capture)."""
    if buckets < 1 or not t_end > t_start:
        raise ValueError("need buckets >= 1 and t_end > t_start")
    dt = (t_end - t_start) / buckets
    i0 = ring.index_at(t_start)
    last = {n: ring.value(n, i0 - 1) for n in names} if i0 > ring.base else {}
    cols = reduce_buckets(ring, names, t_start, dt, 0, buckets, pairs, last)
    x, ys = assemble(cols, names, t_start - t_ref, dt, buckets, pairs)
    return Decimated(x, ys, pairs, ring.index_at(t_end) - i0)


class RollingDecimator:
    """Buckets of one ring on the absolute grid ``k x dt``, each reduced once."""

    def __init__(self, ring: SampleRing, names: Sequence[str], dt: float, pairs: bool,
                 keep: int) -> None:
        if not dt > 0:
            raise ValueError("dt must be > 0")
        self.ring, self.names, self.dt, self.pairs = ring, list(names), dt, pairs
        self.keep = keep
        self.k_base = 0  # bucket index of the first kept bucket
        self.k_next: int | None = None  # next bucket to reduce
        self.cols = Columns({n: array("f") for n in names}, {n: array("f") for n in names})
        self._last: dict[str, float] = {}

    def complete_until(self) -> int | None:
        """Index after the newest complete bucket (all its samples are in the ring)."""
        t = self.ring.last_time
        return None if t is None else math.floor(t / self.dt)

    def update(self, k_limit: int | None = None) -> int | None:
        """Reduce the buckets completed since the last update; returns the new k_next."""
        k_done = self.complete_until()
        if k_done is None:
            return self.k_next
        if k_limit is not None:
            k_done = min(k_done, k_limit)
        if self.k_next is not None and k_done - self.k_next > 2 * self.keep:
            self.k_next = None  # not updated for long: start again from the window
            self.cols = Columns({n: array("f") for n in self.names},
                                {n: array("f") for n in self.names})
            self._last = {}
        if self.k_next is None:
            self.k_next = self.k_base = k_done - self.keep
            i0 = self.ring.index_at(self.k_next * self.dt)
            if i0 > self.ring.base:
                self._last = {n: self.ring.value(n, i0 - 1) for n in self.names}
        if k_done > self.k_next:
            new = reduce_buckets(self.ring, self.names, 0.0, self.dt, self.k_next, k_done,
                                 self.pairs, self._last)
            for name in self.names:
                self.cols.a[name].extend(new.a[name])
                if self.pairs:
                    self.cols.b[name].extend(new.b[name])
            self.k_next = k_done
            extra = self.k_next - self.k_base - 2 * self.keep
            if extra > 0:
                for name in self.names:
                    del self.cols.a[name][:extra]
                    if self.pairs:
                        del self.cols.b[name][:extra]
                self.k_base += extra
        return self.k_next

    def window(self, k0: int, k1: int) -> Columns:
        """Buckets k0..k1-1 (NaN where not reduced)."""
        out = Columns({}, {})
        for name in self.names:
            for src, dst in ((self.cols.a, out.a), (self.cols.b, out.b)):
                if dst is out.b and not self.pairs:
                    continue
                col = src[name]
                lo, hi = k0 - self.k_base, k1 - self.k_base
                before = max(0, min(k1 - k0, -lo))
                after = max(0, min(k1 - k0 - before, hi - len(col)))
                seg = col[max(0, lo):max(0, min(hi, len(col)))]
                if before or after:
                    seg = array("f", [NAN]) * before + seg + array("f", [NAN]) * after
                dst[name] = seg
        return out
