"""3-axis linear and circular interpolation (DYN2 manual 7.6 examples 7 and 8).

Every drive on the line receives the same broadcast words and computes the same path; each
one runs only its own coordinate. The path coordinate ``s`` runs 0 -> length (encoder counts
along the path) through the drive's S-curve generator, so all axes start and finish together
when they share Max Speed, Max Accel and GEAR_NUM (as axes of one machine do).

Decisions:
* path speed = |F| / 127 x the point-to-point profile speed; path acceleration = Max Accel;
* arc direction: positive feedrate = CW = decreasing angle in the plane's (first, second) axes
  with the second axis pointing "up"; plane 0 XY, 1 YZ, 2 ZX;
* start radius != end radius (integer rounding): the radius changes linearly with the angle,
  so the arc ends exactly on the commanded end point;
* start == end gives no motion (the manual makes a circle from two half arcs).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from servobus.families.dmm.profile import unpack_arc_word

PLANES: dict[int, tuple[int, int]] = {0: (0, 1), 1: (1, 2), 2: (2, 0)}
FEEDRATE_MAX = 127


@dataclass(frozen=True)
class AxisPath:
    """One axis' share of a path: ``length`` in path counts, ``at(s)`` -> offset in counts.

    ``slope`` is d at / ds at the start (this axis' counts per path count); ``direction``
    the unit vector of a line in (X, Y, Z), the same on every axis (None for an arc)."""

    length: float
    feed_scale: float  # |F| / 127
    at: Callable[[float], float]
    slope: float = 0.0
    direction: tuple[float, float, float] | None = None


def line_path(words: list[int], axis: int, counts_per_unit: float) -> AxisPath | None:
    """Words dX, dY, dZ, F (relative command units)."""
    *deltas, feed = words
    f = abs(feed)
    if not 1 <= f <= FEEDRATE_MAX:
        return None
    length = math.sqrt(sum(d * d for d in deltas)) * counts_per_unit
    if length == 0.0:
        return None
    ratio = deltas[axis] * counts_per_unit / length
    norm = math.sqrt(sum(d * d for d in deltas))
    dx, dy, dz = (d / norm for d in deltas)

    def at(s: float) -> float:
        return ratio * s

    return AxisPath(length, f / FEEDRATE_MAX, at, slope=ratio, direction=(dx, dy, dz))


def arc_path(words: list[int], axis: int, counts_per_unit: float) -> AxisPath | None:
    """Words a0, b0, a1, b1 (start and end relative to the centre), plane*256 + F."""
    a0, b0, a1, b1, packed = words
    plane, feed = unpack_arc_word(packed)
    if plane not in PLANES or not 1 <= abs(feed) <= FEEDRATE_MAX:
        return None
    first, second = PLANES[plane]
    if axis not in (first, second):
        return None
    r0, r1 = math.hypot(a0, b0), math.hypot(a1, b1)
    th0, th1 = math.atan2(b0, a0), math.atan2(b1, a1)
    cw = feed > 0
    sweep = ((th0 - th1) if cw else (th1 - th0)) % (2 * math.pi)
    if sweep == 0.0 or r0 == 0.0 or r1 == 0.0:
        return None
    sign = -1.0 if cw else 1.0
    length = sweep * (r0 + r1) / 2 * counts_per_unit
    use_cos = axis == first
    start = a0 if use_cos else b0
    k = counts_per_unit

    def at(s: float) -> float:
        frac = s / length
        th = th0 + sign * sweep * frac
        r = r0 + (r1 - r0) * frac
        return ((r * math.cos(th) if use_cos else r * math.sin(th)) - start) * k

    # d/ds at s = 0: radius change plus rotation, per path count
    dr, dth = (r1 - r0) / length, sign * sweep / length
    slope = ((dr * math.cos(th0) - r0 * math.sin(th0) * dth) if use_cos
             else (dr * math.sin(th0) + r0 * math.cos(th0) * dth)) * k
    return AxisPath(length, abs(feed) / FEEDRATE_MAX, at, slope=slope)
