"""The vendor-neutral AsyncAxis: one drive on one connection (docs/axis.md).

Units are the same on every protocol and vendor: positions in encoder counts of the drive
family (``counts_per_rev``: DMM 65,536, YZ-AIM 32,768), speeds in rpm, current in amperes
(positive = towards increasing position). Each protocol implements the abstract primitives
once; the logic that combines them (move and wait, confirmed moves, wait_idle, stop,
parameter backup) lives here once. :class:`servobus.axis.sync.Axis` runs any AsyncAxis
synchronously, method for method, without a copy of it.

What a host can know about a move (docs/axis.md): on DYN232M and DYN CAN a motion command
gets no reply, so ``move_to`` returning means the bytes left the host, not that the drive
took them. ``confirm=True`` checks afterwards, by status and position, that the drive is
moving or already on the target, and raises DriveTimeout if not; the command is never
re-sent (a re-sent relative move would move twice).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from types import TracebackType

from servobus.errors import ArgumentRangeError, DriveAlarm, DriveTimeout
from servobus.families.base import AxisStatus, Family, ParamInfo
from servobus.transport.base import Direction

log = logging.getLogger(__name__)

#: Client-level trace hook: decoded packets/frames and the errors met (see transport.trace).
AxisTraceHook = Callable[[Direction, object, float], None]

DEFAULT_WAIT_TIMEOUT_S = 30.0
DEFAULT_CONFIRM_TIMEOUT_S = 0.5


def check_timeout(name: str, value: float | None, *, allow_none: bool = True) -> float | None:
    """A finite, positive number of seconds (or None where allowed); else ArgumentRangeError."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or value <= 0:
        raise ArgumentRangeError(f"{name}={value!r} must be a finite number of seconds > 0")
    return float(value)


def check_int(name: str, value: object) -> int:
    """An int (not bool, not float, not None) or ArgumentRangeError; nothing is sent."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ArgumentRangeError(f"{name} must be an integer, got {value!r}")
    return value


class AsyncAxis(ABC):
    """One drive on one connection. Every I/O method is a coroutine."""

    # ------------------------------------------------------------- identity
    @property
    @abstractmethod
    def drive_id(self) -> int: ...

    @property
    @abstractmethod
    def protocol(self) -> str: ...

    @property
    @abstractmethod
    def family(self) -> Family: ...

    @property
    @abstractmethod
    def drive_ids(self) -> range:
        """Every id a drive can have on this protocol (what ``scan`` tries)."""

    @property
    def counts_per_rev(self) -> int:
        return self.family.counts_per_rev

    # ------------------------------------------------------------- primitives (per protocol)
    @abstractmethod
    async def _send_move_to(self, position: int) -> None:
        """Send the absolute move to ``position`` counts; convert and range-check first."""

    @abstractmethod
    async def _send_move_by(self, distance: int) -> None:
        """Send the relative move by ``distance`` counts; convert and range-check first."""

    @abstractmethod
    async def turn(self, rpm: int) -> None:
        """Constant speed in rpm (0 ramps down and holds)."""

    @abstractmethod
    async def set_origin(self) -> None: ...

    @abstractmethod
    async def enable(self) -> None: ...

    @abstractmethod
    async def disable(self) -> None: ...

    @abstractmethod
    async def reset(self) -> None:
        """Power cycle: clears a latched alarm."""

    @abstractmethod
    async def status(self) -> AxisStatus: ...

    @abstractmethod
    async def position(self) -> int:
        """Encoder counts of the family (``counts_per_rev`` per revolution)."""

    @abstractmethod
    async def speed(self) -> float:
        """Motor speed, rpm."""

    @abstractmethod
    async def current(self) -> float:
        """Torque-producing motor current, A (positive = towards increasing position)."""

    @abstractmethod
    def parameters(self) -> tuple[ParamInfo, ...]:
        """The family's parameters this protocol reaches (what ``params``/``set`` offer)."""

    @abstractmethod
    async def read_param(self, name: str) -> int: ...

    @abstractmethod
    async def write_param(self, name: str, value: int) -> None: ...

    @abstractmethod
    async def read_id(self) -> int: ...

    @abstractmethod
    async def assign_id(self, new_id: int) -> None:
        """After this the axis talks to ``new_id``."""

    @abstractmethod
    async def ping(self, timeout: float = 0.05) -> bool:
        """One status read, no retry; False on timeout."""

    @abstractmethod
    async def sibling(self, drive_id: int) -> AsyncAxis:
        """Another drive on the same connection; closing a sibling keeps the connection."""

    @abstractmethod
    async def add_trace(self, hook: AxisTraceHook) -> None: ...

    @abstractmethod
    async def close(self) -> None: ...

    # ------------------------------------------------------------- units
    def param_info(self, name: str) -> ParamInfo:
        """A reachable parameter by name; ArgumentRangeError naming what exists."""
        for p in self.parameters():
            if p.name == name:
                return p
        raise ArgumentRangeError(
            f"{name!r} is not a parameter {self.protocol} reaches on {self.family.title}; "
            f"known: {', '.join(p.name for p in self.parameters())}")

    def revs(self, revolutions: float) -> int:
        """Revolutions -> counts of this axis (rounded half away from zero)."""
        return self.family.revs_to_counts(revolutions)

    def degrees(self, degrees: float) -> int:
        """Degrees -> counts of this axis (rounded half away from zero)."""
        return self.family.degrees_to_counts(degrees)

    # ------------------------------------------------------------- shared logic (once)
    async def move_to(self, position: int, *, wait: bool = False, timeout: float | None = None,
                      confirm: bool = False) -> None:
        """Move to ``position`` counts; ``wait`` until idle; ``confirm`` the drive took it."""
        check_int("position", position)
        wait_s = check_timeout("timeout", timeout)
        before = await self.position() if confirm else 0
        await self._send_move_to(position)
        if confirm:
            await self._confirm(before, position)
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if wait_s is None else wait_s)

    async def move_by(self, distance: int, *, wait: bool = False, timeout: float | None = None,
                      confirm: bool = False) -> None:
        """Move by ``distance`` counts; ``wait`` until idle; ``confirm`` the drive took it."""
        check_int("distance", distance)
        wait_s = check_timeout("timeout", timeout)
        before = await self.position() if confirm else 0
        await self._send_move_by(distance)
        if confirm:
            await self._confirm(before, before + distance)
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if wait_s is None else wait_s)

    async def _confirm(self, before: int, target: int,
                       timeout: float = DEFAULT_CONFIRM_TIMEOUT_S) -> None:
        """The drive took the move: it is moving, or its position left ``before``, or it is
        already on ``target``. Never re-sends; DriveTimeout (naming what was seen) if not."""
        deadline = time.monotonic() + timeout
        tolerance = max(1, self.counts_per_rev // 1024)
        while True:
            st = await self.status()
            self._raise_alarm(st)
            pos = await self.position()
            if st.moving or abs(pos - before) > tolerance or abs(pos - target) <= tolerance:
                return
            if time.monotonic() >= deadline:
                raise DriveTimeout(
                    f"drive {self.drive_id} did not take the move within {timeout:g} s "
                    f"(position {pos}, target {target}, status {st.as_dict()}); not re-sent")
            await asyncio.sleep(0.01)

    def _raise_alarm(self, st: AxisStatus) -> None:
        if st.alarm_latched:
            raise DriveAlarm(
                f"drive {self.drive_id} alarm {st.alarm_code}: {st.alarm_text}; "
                "reset() clears it", code=st.alarm_code, drive_id=self.drive_id)

    async def stop(self) -> None:
        """Constant speed 0: the drive ramps down at its deceleration and holds position."""
        await self.turn(0)

    async def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                        poll: float = 0.02) -> AxisStatus:
        """Poll status until motion is done and the motor is on position.

        Raises DriveAlarm as soon as a latched alarm shows, DriveTimeout when ``timeout``
        passes.
        """
        timeout_s = check_timeout("timeout", timeout, allow_none=False)
        poll_s = 0.0 if poll == 0 else check_timeout("poll", poll, allow_none=False)
        assert timeout_s is not None and poll_s is not None
        deadline = time.monotonic() + timeout_s
        while True:
            st = await self.status()
            self._raise_alarm(st)
            if st.idle:
                return st
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriveTimeout(
                    f"drive {self.drive_id} still moving after {timeout_s:g} s "
                    f"(moving={st.moving}, in_position={st.in_position})")
            await asyncio.sleep(min(poll_s, remaining))

    async def read_params(self, names: Iterable[str] | None = None) -> dict[str, int]:
        """Read parameters (default: every one this protocol reaches)."""
        wanted = [p.name for p in self.parameters()] if names is None else list(names)
        for name in wanted:
            self.param_info(name)
        return {name: await self.read_param(name) for name in wanted}

    async def write_params(self, values: Mapping[str, int]) -> None:
        """Write several parameters; every value is checked before the first byte is sent."""
        for name, value in values.items():
            self._check_param(name, value)
        for name, value in values.items():
            await self.write_param(name, value)

    def _check_param(self, name: str, value: object) -> int:
        """Range-check one parameter write against the family table (protocols add more)."""
        return self.param_info(name).check(value)

    async def __aenter__(self) -> AsyncAxis:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.close()
