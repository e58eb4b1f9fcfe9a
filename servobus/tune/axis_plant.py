"""The tuner's plant over an Axis (a real drive or ``sim://``), on the wall clock.

Where the axis has ``Capability.DRIVE_TRACE`` the test move is measured from the drive's own
trace (the virtual drives: 4 kHz, position error included); elsewhere by polling the link
(position and current, as fast as the link answers; no position error). Each test move is a
point-to-point move to a target inside the limits the tuner checked: the drive ends it by
itself at the target (docs/safety.md: "one point-to-point move"), and a stop ends it early.
"""

from __future__ import annotations

import asyncio
import time

from servobus.axis.base import AsyncAxis
from servobus.axis.capabilities import Capability
from servobus.axis.types import MOVING_RPM, ParamInfo, TuningProfile
from servobus.errors import NotSupported
from servobus.tune.record import Record

#: Polls in a row below MOVING_RPM that count as standing still.
SETTLED_POLLS = 5
#: How long after a test move's end its last trace samples may still arrive (the virtual
#: drives stamp samples up to one 4 ms clock tick late; a margin over that).
TRACE_LAG_S = 0.1


def tuning_profile(axis: AsyncAxis) -> TuningProfile:
    """The gains ``Capability.TUNING`` gives, or NotSupported (before anything is sent)."""
    axis.require(Capability.TUNING)
    profile = axis.family.tuning
    if profile is None:
        raise NotSupported(f"{axis.family.title} declares no tuning gains",
                           family=axis.family.name)
    return profile


class AxisPlant:
    """A :class:`servobus.tune.plant.Plant` over ``axis``; ``trace=False`` polls even where
    the drive keeps a trace."""

    def __init__(self, axis: AsyncAxis, *, trace: bool = True) -> None:
        self.axis = axis
        self.profile = tuning_profile(axis)
        self.trace = trace and axis.supports(Capability.DRIVE_TRACE)
        self.source = "trace" if self.trace else "poll"
        self.rate_hz = 0.0  # known after the first test move

    def param_info(self, name: str) -> ParamInfo:
        return self.axis.param_info(name)

    async def read_gain(self, name: str) -> int:
        return await self.axis.read_param(name)

    async def write_gain(self, name: str, value: int) -> None:
        await self.axis.write_param(name, value)

    async def position(self) -> int:
        return await self.axis.position()

    async def test_move(self, target: int, seconds: float) -> Record:
        axis = self.axis
        start = float(await axis.position())
        if self.trace:
            await axis.trace_buffer()  # starts the recording / drops older samples
        t_cmd = time.monotonic()
        await axis.move_to(target)
        if self.trace:
            record = await self._traced(t_cmd, seconds, start, target)
        else:
            record = await self._polled(t_cmd, seconds, start, target)
        status = await axis.status()
        return Record(record.times, record.position, record.error, record.current, start,
                      float(target), status.alarm_code, status.alarm_text)

    async def _traced(self, t_cmd: float, seconds: float, start: float, target: int) -> Record:
        times: list[float] = []
        pos: list[float] = []
        err: list[float] = []
        cur: list[float] = []
        while time.monotonic() - t_cmd < seconds + TRACE_LAG_S:
            await asyncio.sleep(0.05)
            cap = await self.axis.trace_buffer()
            self.rate_hz = cap.rate_hz or self.rate_hz
            s = cap.signals
            for i in range(cap.count):
                t = cap.t0 + i / cap.rate_hz - t_cmd
                if 0.0 < t <= seconds:
                    times.append(t)
                    pos.append(s["position"][i])
                    err.append(s["position_error"][i])
                    cur.append(s["current"][i])
        if not times:
            raise NotSupported("the drive's trace gave no samples of the test move")
        # a virtual drive at rest in exact equilibrium records nothing more: it holds still
        step = 1.0 / self.rate_hz
        while times[-1] + step <= seconds:
            times.append(times[-1] + step)
            pos.append(pos[-1])
            err.append(err[-1])
            cur.append(cur[-1])
        return Record(times, pos, err, cur, start, float(target))

    async def _polled(self, t_cmd: float, seconds: float, start: float, target: int) -> Record:
        times: list[float] = []
        pos: list[float] = []
        cur: list[float] = []
        while (now := time.monotonic() - t_cmd) < seconds:
            pos.append(float(await self.axis.position()))
            cur.append(await self.axis.current())
            times.append(now)
        self.rate_hz = len(times) / seconds
        return Record(times, pos, None, cur, start, float(target))

    async def settle(self, timeout: float) -> None:
        end = time.monotonic() + timeout
        still = 0
        while still < SETTLED_POLLS and time.monotonic() < end:
            still = still + 1 if abs(await self.axis.speed()) < MOVING_RPM else 0

    async def stop(self) -> None:
        await self.axis.stop()

    async def save(self) -> None:
        await self.axis.save_parameters()

    def rotor_amps_per_accel(self) -> None:
        """The Axis knows no motor model: the inertia test gives A per rev/s^2 only."""
        return None
