"""Tuning: a step test (move_by + the capture around it), its figures, gains apply/revert.

The step is commanded with ``move_by`` (its end point checked against the soft limits first,
servobus.gui.soft_limits) and the capture is triggered by the command itself:
the sampler's samples (the drive's trace, or polls) from shortly before the command to
``duration`` after it are cut out and measured (servobus.axis.step_metrics). A DMM drive
moves along its Max Speed / Max Accel profile, so the figures describe the profile and
the servo loop together; a small step shows the loop more than the profile.

Which parameters are gains is read from the names of the family's table
(:data:`GAIN_NAME_HINTS`); the GUI knows no family by name.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from dataclasses import dataclass, field
from datetime import UTC, datetime

from servobus.axis.step_metrics import step_metrics
from servobus.errors import ArgumentRangeError, DriveTimeout, ServobusError
from servobus.gui.fleet import AxisHandle
from servobus.gui.sampler import AxisSampler
from servobus.gui.soft_limits import check_not_tuning, check_step, has_limits

#: A parameter is a tuning gain when its name contains one of these.
GAIN_NAME_HINTS = ("gain", "kp", "integration", "feedforward", "trq_cons")
STEP_SIGNALS = ("position", "position_error", "speed", "current")
PRE_FRACTION = 0.1  # of the duration, recorded before the command
MAX_DURATION_S = 10.0
FRESH_TIMEOUT_S = 2.0
TRACE_POINTS = 1500
HISTORY = 20


def gain_names(handle: AxisHandle) -> list[str]:
    return [p.name for p in handle.axis.parameters()
            if any(h in p.name for h in GAIN_NAME_HINTS)]


@dataclass
class TuningState:
    """Per axis: step results and the gains before the last apply (for revert)."""

    results: deque[dict[str, object]] = field(default_factory=lambda: deque(maxlen=HISTORY))
    previous: dict[str, int] | None = None
    runs: int = 0


async def _wait_for(sampler: AxisSampler, t: float, timeout: float) -> None:
    """Until the sampler has samples up to ``t``; a sampler that stopped says why at once."""
    ring = sampler.ring
    deadline = time.monotonic() + timeout
    while (ring.last_time or -math.inf) < t:
        if not sampler.running:
            raise ServobusError(f"no samples: {sampler.error or 'the sampling stopped'}")
        if time.monotonic() > deadline:
            why = f": {sampler.error}" if sampler.error else " (the link gives none)"
            raise DriveTimeout(f"no samples up to the end of the step after {timeout:g} s{why}")
        await asyncio.sleep(0.01)


def _thin(values: list[float], step: int, factor: float = 1.0) -> list[float | None]:
    return [None if math.isnan(v) else v * factor for v in values[::step]]


#: Step figures that are positions (signed) and sizes (the band, the largest error).
_POSITIONS, _SIZES = ("start", "target", "final", "steady_state_error"), \
    ("settle_band", "following_error_max")


def _shown_metrics(metrics: dict[str, float | None], per_count: float
                   ) -> dict[str, float | None]:
    """The step's figures in the axis's unit (counts x ``per_count``); times and % as
    they are."""
    out = dict(metrics)
    for key in (*_POSITIONS, *_SIZES):
        v = out.get(key)
        if v is not None:
            out[key] = v * (per_count if key in _POSITIONS else abs(per_count))
    return out


async def run_step(handle: AxisHandle, sampler: AxisSampler, state: TuningState,
                   distance: int, duration_s: float) -> dict[str, object]:
    """Command a relative step of ``distance`` counts and measure ``duration_s`` of it."""
    if isinstance(distance, bool) or not isinstance(distance, int) or distance == 0:
        raise ArgumentRangeError(f"step distance must be a non-zero integer of counts, "
                                 f"got {distance!r}")
    if not 0.05 <= duration_s <= MAX_DURATION_S:
        raise ArgumentRangeError(f"duration {duration_s} s: 0.05..{MAX_DURATION_S} s")
    axis = handle.axis
    ring = sampler.ring
    # soft limits (issue 27): refused at once, before the recording, and checked again from
    # the position at the command; either way no motion command is sent
    check_step(handle, 0.0, 0)
    if has_limits(handle):
        check_step(handle, float(await handle.call(axis.position())), distance)
    token = sampler.subscribe(STEP_SIGNALS)
    try:
        pre_s = PRE_FRACTION * duration_s
        await _wait_for(sampler, time.monotonic() - 0.02, FRESH_TIMEOUT_S + pre_s)
        await asyncio.sleep(pre_s)
        try:
            band = float(await handle.call(axis.position_window()))
        except ServobusError:
            band = 0.0
        gains = {n: await handle.call(axis.read_param(n)) for n in gain_names(handle)}
        t_cmd = time.monotonic()
        i_cmd = ring.index_at(t_cmd)
        start = ring.value("position", i_cmd - 1) if i_cmd > ring.base else math.nan
        if math.isnan(start):
            start = float(await handle.call(axis.position()))
        check_step(handle, start, distance)
        await handle.call(axis.move_by(distance))
        await _wait_for(sampler, t_cmd + duration_s, duration_s + FRESH_TIMEOUT_S)
    finally:
        sampler.unsubscribe(token)
    i0, i1 = ring.index_at(t_cmd - pre_s), ring.index_at(t_cmd + duration_s)
    times = list(ring.time_slice(i0, i1))
    pos = list(ring.column("position", i0, i1))
    err = list(ring.column("position_error", i0, i1))
    has_err = any(not math.isnan(e) for e in err)
    metrics = step_metrics(times, pos, t_cmd, start, start + distance, band=band,
                           position_errors=err if has_err else None)
    step = max(1, len(times) // TRACE_POINTS)
    state.runs += 1
    units = handle.units()  # positions in the axis's unit, speeds in its speed unit
    f, fs = units.per_count, units.per_rpm
    result: dict[str, object] = {
        "run": state.runs, "axis": handle.id, "name": handle.label,
        "time": datetime.now(UTC).isoformat(timespec="seconds"),
        "distance": distance, "step": distance * f, "unit": units.position,
        "speed_unit": units.speed, "duration_s": duration_s, "gains": gains,
        "source": sampler.source, "rate_hz": sampler.rate_hz, "samples": len(times),
        "metrics": _shown_metrics(metrics.as_dict(), f),
        "trace": {"t": [t - t_cmd for t in times[::step]],
                  "position": [None if math.isnan(p) else (p - start) * f
                               for p in pos[::step]],
                  "position_error": _thin(err, step, f) if has_err else None,
                  "speed": _thin(list(ring.column("speed", i0, i1)), step, fs)},
    }
    state.results.append(result)
    return result


async def apply_gains(handle: AxisHandle, state: TuningState,
                      values: dict[str, int]) -> dict[str, int]:
    """Write gains (checked first); remember what they were for :func:`revert_gains`."""
    if not values:
        raise ArgumentRangeError("no gains to apply")
    check_not_tuning(handle, "writing gains")
    for name, value in values.items():
        handle.axis.param_info(name).check(value)
    before = await handle.call(handle.axis.read_params(list(values)))
    await handle.call(handle.axis.write_params(values))
    state.previous = before
    return before


async def revert_gains(handle: AxisHandle, state: TuningState) -> dict[str, int]:
    if not state.previous:
        raise ArgumentRangeError("nothing to revert: no gains were applied")
    check_not_tuning(handle, "writing gains")
    values, state.previous = state.previous, None
    await handle.call(handle.axis.write_params(values))
    return values
