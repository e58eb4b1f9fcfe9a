"""Step-response figures from a recorded position (pure; the Tuning panel's, the tuner's).

Definitions (control-engineering conventions; the drive manuals define none):

* the step goes from ``start`` (position when the move was commanded, at ``t_cmd``) to
  ``target``; r(t) = (position - start) / (target - start);
* delay: from the command until r first reaches 2 % (dead time plus the profile's start);
* rise time: from r = 10 % to r = 90 % (first crossings, interpolated between samples);
* overshoot: how far the peak of r goes beyond 1, in % of the step (0 when it never does);
* settling time: from the command until the position enters the band around the target
  for good (None when the record ends outside it);
* steady-state error: mean of the last 10 % of the record minus the target, counts;
* following error: the largest |position error| (reference - actual) in the record, counts,
  where the drive reports its position error (its trace), else None.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

RISE_FROM, RISE_TO, MOVE_SEEN = 0.1, 0.9, 0.02
#: The settling band: this fraction of the step, or the drive's in-position window if wider.
SETTLE_FRACTION = 0.02


@dataclass(frozen=True)
class StepMetrics:
    start: float
    target: float
    final: float
    delay_s: float | None
    rise_time_s: float | None
    overshoot_pct: float
    peak_time_s: float | None
    settling_time_s: float | None
    settle_band: float
    steady_state_error: float
    following_error_max: float | None

    def as_dict(self) -> dict[str, float | None]:
        return asdict(self)


def _first_reach(t: Sequence[float], r: Sequence[float], level: float, i0: int) -> float | None:
    """Interpolated time r first reaches ``level`` at or after index ``i0``."""
    for i in range(i0, len(r)):
        if r[i] >= level:
            if i == i0 or r[i - 1] >= level:
                return t[i]
            k = (level - r[i - 1]) / (r[i] - r[i - 1])
            return t[i - 1] + k * (t[i] - t[i - 1])
    return None


def step_metrics(times: Sequence[float], positions: Sequence[float], t_cmd: float,
                 start: float, target: float, *, band: float | None = None,
                 position_errors: Sequence[float] | None = None) -> StepMetrics:
    """Figures of one step; ``band`` (counts) defaults to SETTLE_FRACTION of the step."""
    if len(times) != len(positions) or not times:
        raise ValueError("need as many positions as times, at least one")
    step = target - start
    if step == 0:
        raise ValueError("a step needs target != start")
    pairs = [(t, y) for t, y in zip(times, positions, strict=True)
             if t >= t_cmd and math.isfinite(y)]
    if not pairs:
        raise ValueError("no samples after the command")
    t = [p[0] for p in pairs]
    y = [p[1] for p in pairs]
    r = [(v - start) / step for v in y]
    width = max(abs(step) * SETTLE_FRACTION, band or 0.0)

    def since(x: float | None) -> float | None:
        return None if x is None else x - t_cmd

    t10 = _first_reach(t, r, RISE_FROM, 0)
    t90 = _first_reach(t, r, RISE_TO, 0)
    peak_i = max(range(len(r)), key=r.__getitem__)
    overshoot = max(0.0, r[peak_i] - 1.0) * 100.0
    outside = [i for i, v in enumerate(y) if abs(v - target) > width]
    if not outside:
        settling: float | None = 0.0
    elif outside[-1] == len(y) - 1:
        settling = None
    else:
        settling = t[outside[-1] + 1] - t_cmd
    tail = y[len(y) - max(1, len(y) // 10):]
    final = sum(tail) / len(tail)
    follow = None
    if position_errors is not None:
        errs = [abs(e) for tt, e in zip(times, position_errors, strict=True)
                if tt >= t_cmd and math.isfinite(e)]
        follow = max(errs) if errs else None
    return StepMetrics(
        start=start, target=target, final=final,
        delay_s=since(_first_reach(t, r, MOVE_SEEN, 0)),
        rise_time_s=None if t10 is None or t90 is None else t90 - t10,
        overshoot_pct=overshoot,
        peak_time_s=since(t[peak_i]) if r[peak_i] >= RISE_TO else None,
        settling_time_s=settling, settle_band=width,
        steady_state_error=final - target, following_error_max=follow)
