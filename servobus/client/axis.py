"""Protocol-agnostic Axis API (AXIS_API.md): the AsyncAxis core and the sync ``Axis`` facade.

Each protocol implements the abstract primitives of :class:`AsyncAxis` once; the logic that
combines them (move with wait or confirmation, wait_idle, stop, read_params/write_params)
lives here once. :class:`Axis` runs any AsyncAxis on a private event-loop thread with the
same method names.

What a host can know about a move (DYN2 manual 7.2: motion commands have no reply; the same
on DYN CAN, section 6). Lifted into docs/dyn232.md and docs/dyncan.md:

* ``move_to``/``move_by``/``turn`` return once the command is handed to the medium: the
  argument was in range and the link was up. They cannot know whether the drive received
  the packet, was alive (a frozen or powered-off drive, a cable cut after the adapter, a
  corrupted packet the drive drops all look the same), or started to move.
* A motion command is never re-sent: a resend could move twice (relative moves) or restart
  a profile. Reads are retried; motion is not.
* ``confirm=True`` (or a ``confirm_timeout``) observes the drive after the one send: the
  move is confirmed when a status read shows the profile running (``motion_busy`` and it
  was not busy before), or a position read shows the motor at the target within OnRange or
  clearly nearer to it than before. Otherwise DriveTimeout after ``confirm_timeout``,
  without a resend; the caller decides. A move to where the motor already is (within
  OnRange) cannot be observed: it is confirmed by the position alone. A drive still
  heading the same way from an earlier command also passes: confirmation means "seen
  heading to or at the target", not "this packet was decoded".
* ``wait=True`` waits until the drive reports the move done (``wait_idle``); on its own it
  does not prove that the move was received (a drive that never started is idle too).
"""

from __future__ import annotations

import asyncio
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from types import TracebackType
from typing import Any

from servobus.client import checks
from servobus.client.sync import LoopThread
from servobus.drive import params as P
from servobus.drive import units as U
from servobus.drive.registers import DriveConfig, DriveStatus
from servobus.errors import ArgumentRangeError, DriveAlarm, DriveTimeout
from servobus.transport.base import Direction

#: Client-level trace hook: decoded packets/frames and the errors met (see transport.trace).
AxisTraceHook = Callable[[Direction, object, float], None]

DEFAULT_WAIT_TIMEOUT_S = 30.0
#: Default deadline of a confirmed move: a drive starts a profile within one servo cycle, so
#: half a second covers the status reads and their retries on a slow or paced link.
DEFAULT_CONFIRM_TIMEOUT_S = 0.5
DEFAULT_POLL_S = 0.02


class AsyncAxis(ABC):
    """One drive on one connection. All methods are coroutines (also add_trace/sibling)."""

    # ------------------------------------------------------------- identity
    @property
    @abstractmethod
    def drive_id(self) -> int: ...

    @property
    @abstractmethod
    def protocol(self) -> str: ...

    # ------------------------------------------------------------- primitives (per protocol)
    @abstractmethod
    async def _send_move_to(self, position: int) -> None:
        """Send the absolute move (command units); range-check before sending."""

    @abstractmethod
    async def _send_move_by(self, distance: int) -> None:
        """Send the relative move (command units); range-check before sending."""

    @abstractmethod
    async def turn(self, rpm: int) -> None: ...

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
    async def status(self) -> DriveStatus: ...

    @abstractmethod
    async def config(self) -> DriveConfig: ...

    @abstractmethod
    async def set_config(self, cfg: DriveConfig) -> None: ...

    @abstractmethod
    async def position(self) -> int:
        """Encoder counts (65,536 per revolution)."""

    @abstractmethod
    async def speed(self) -> int:
        """rpm."""

    @abstractmethod
    async def torque(self) -> int:
        """The protocol's torque unit."""

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

    def _check_param(self, name: str, value: int) -> None:
        """Range-check one parameter write; protocols add reachability checks."""
        P.spec(checks.param_name(name)).check(value)

    def _check_move(self, value: int, *, relative: bool) -> None:
        """Check a move argument without sending (protocols add their range)."""
        if isinstance(value, bool) or not isinstance(value, int):
            what = "distance" if relative else "position"
            raise ArgumentRangeError(f"{what} must be an integer, got {value!r}")

    # ------------------------------------------------------------- shared logic (once)
    async def move_to(self, position: int, *, wait: bool = False,
                      timeout: float | None = None, confirm: bool = False,
                      confirm_timeout: float | None = None) -> None:
        """Absolute move in command units (x 4096/GEAR_NUM x 4 counts).

        Returns when the command is sent; the drive never answers a move (module doc:
        what a host can know). ``confirm=True`` (or ``confirm_timeout``) then verifies
        that the drive took it (:meth:`_confirm`; DriveTimeout if not, never re-sent);
        ``wait=True`` then waits until the move is done (``timeout``, default 30 s).
        """
        await self._move(position, False, wait, timeout, confirm, confirm_timeout)

    async def move_by(self, distance: int, *, wait: bool = False,
                      timeout: float | None = None, confirm: bool = False,
                      confirm_timeout: float | None = None) -> None:
        """Relative move in command units; as :meth:`move_to` (a resend would move twice,
        so it is never re-sent)."""
        await self._move(distance, True, wait, timeout, confirm, confirm_timeout)

    async def _move(self, value: int, relative: bool, wait: bool, timeout: float | None,
                    confirm: bool, confirm_timeout: float | None) -> None:
        self._check_move(value, relative=relative)
        wait_s = checks.optional_seconds("timeout", timeout)
        confirm_s = checks.optional_seconds("confirm_timeout", confirm_timeout)
        if confirm or confirm_s is not None:
            await self._confirmed_move(value, relative,
                                       DEFAULT_CONFIRM_TIMEOUT_S if confirm_s is None
                                       else confirm_s)
        elif relative:
            await self._send_move_by(value)
        else:
            await self._send_move_to(value)
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if wait_s is None else wait_s)

    async def _confirmed_move(self, value: int, relative: bool, deadline_s: float) -> None:
        """Read where the drive is, send the move once, then observe that it took it.

        The reads before the send may fail (DriveTimeout, ...): then nothing was sent.
        """
        gear = await self.read_param("gear_num")
        tolerance = U.onrange_to_counts(await self.read_param("on_range"))
        was_busy = (await self.status()).motion_busy
        start = await self.position()
        counts = U.command_to_counts(value, gear)
        target = start + counts if relative else counts
        if relative:
            await self._send_move_by(value)
        else:
            await self._send_move_to(value)
        await self._confirm(target, start, tolerance, was_busy, deadline_s)

    async def _confirm(self, target: float, start: int, tolerance: float, was_busy: bool,
                       deadline_s: float) -> None:
        """Poll status and position until the move shows, the drive alarms (DriveAlarm)
        or ``deadline_s`` passes (DriveTimeout). Read failures are retried until then."""
        deadline = time.monotonic() + deadline_s
        start_gap = abs(start - target)
        seen = "no reply"
        while True:
            try:
                st = await self.status()
                self._raise_alarm(st)
                if st.motion_busy and not was_busy:
                    return
                position = await self.position()
            except DriveTimeout as exc:
                seen = f"reads failed ({exc})"
            else:
                gap = abs(position - target)
                if gap <= tolerance or gap < start_gap - tolerance:
                    return
                seen = f"position {position}, motion_busy={st.motion_busy}"
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriveTimeout(
                    f"drive {self.drive_id} did not take the move to {target:.0f} counts "
                    f"within {deadline_s:g} s (started at {start}; {seen}); the move was "
                    "sent once and is not re-sent")
            await asyncio.sleep(min(DEFAULT_POLL_S, remaining))

    def _raise_alarm(self, st: DriveStatus) -> None:
        if st.alarm.latching:
            raise DriveAlarm(
                f"drive {self.drive_id} alarm {st.alarm.name.lower()} "
                f"(code {int(st.alarm)}); reset() clears it",
                code=int(st.alarm), drive_id=self.drive_id,
            )

    async def stop(self) -> None:
        """Constant speed 0: the drive ramps down at Max Accel and holds position."""
        await self.turn(0)

    async def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                        poll: float = DEFAULT_POLL_S) -> DriveStatus:
        """Poll status until motion is done and the motor is on position.

        Raises DriveAlarm as soon as a latched alarm shows (the checksum notice, code 4, is
        not latched and does not raise), DriveTimeout when ``timeout`` passes.
        ``timeout`` must be finite and > 0, ``poll`` finite and >= 0 (ArgumentRangeError).
        """
        checks.seconds("timeout", timeout)
        checks.non_negative_seconds("poll", poll)
        deadline = time.monotonic() + timeout
        while True:
            st = await self.status()
            self._raise_alarm(st)
            if not st.motion_busy and st.on_position:
                return st
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriveTimeout(
                    f"drive {self.drive_id} still moving after {timeout:g} s "
                    f"(motion_busy={st.motion_busy}, on_position={st.on_position})"
                )
            await asyncio.sleep(min(poll, remaining))

    async def read_params(self, names: Iterable[str] = P.DYN_PARAMS) -> dict[str, int]:
        return {name: await self.read_param(name) for name in names}

    async def write_params(self, values: Mapping[str, int]) -> None:
        """Write several parameters; every value is checked before the first byte is sent."""
        for name, value in values.items():
            self._check_param(name, value)
        for name, value in values.items():
            await self.write_param(name, value)

    async def __aenter__(self) -> AsyncAxis:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.close()


class Axis:
    """Synchronous facade over an AsyncAxis: same names, each call runs on the loop thread."""

    def __init__(self, core: AsyncAxis, runner: LoopThread, *, owns_runner: bool = True,
                 call_timeout: float | None = None) -> None:
        self._core = core
        self._runner = runner
        self._owns_runner = owns_runner
        self._call_timeout = call_timeout  # safety net only; the core enforces deadlines

    def _run(self, coro: Any) -> Any:
        return self._runner.run(coro, self._call_timeout)

    @property
    def core(self) -> AsyncAxis:
        """The async core (for use on the facade's loop thread only)."""
        return self._core

    @property
    def drive_id(self) -> int:
        return self._core.drive_id

    @property
    def protocol(self) -> str:
        return self._core.protocol

    def move_to(self, position: int, *, wait: bool = False, timeout: float | None = None,
                confirm: bool = False, confirm_timeout: float | None = None) -> None:
        """See :meth:`AsyncAxis.move_to` (a move has no reply; ``confirm`` verifies it)."""
        self._run(self._core.move_to(position, wait=wait, timeout=timeout, confirm=confirm,
                                     confirm_timeout=confirm_timeout))

    def move_by(self, distance: int, *, wait: bool = False, timeout: float | None = None,
                confirm: bool = False, confirm_timeout: float | None = None) -> None:
        """See :meth:`AsyncAxis.move_by`."""
        self._run(self._core.move_by(distance, wait=wait, timeout=timeout, confirm=confirm,
                                     confirm_timeout=confirm_timeout))

    def turn(self, rpm: int) -> None:
        self._run(self._core.turn(rpm))

    def stop(self) -> None:
        self._run(self._core.stop())

    def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                  poll: float = DEFAULT_POLL_S) -> DriveStatus:
        result: DriveStatus = self._run(self._core.wait_idle(timeout, poll))
        return result

    def set_origin(self) -> None:
        self._run(self._core.set_origin())

    def enable(self) -> None:
        self._run(self._core.enable())

    def disable(self) -> None:
        self._run(self._core.disable())

    def reset(self) -> None:
        self._run(self._core.reset())

    def status(self) -> DriveStatus:
        result: DriveStatus = self._run(self._core.status())
        return result

    def config(self) -> DriveConfig:
        result: DriveConfig = self._run(self._core.config())
        return result

    def set_config(self, cfg: DriveConfig) -> None:
        self._run(self._core.set_config(cfg))

    def position(self) -> int:
        return int(self._run(self._core.position()))

    def speed(self) -> int:
        return int(self._run(self._core.speed()))

    def torque(self) -> int:
        return int(self._run(self._core.torque()))

    def read_param(self, name: str) -> int:
        return int(self._run(self._core.read_param(name)))

    def write_param(self, name: str, value: int) -> None:
        self._run(self._core.write_param(name, value))

    def read_params(self, names: Iterable[str] = P.DYN_PARAMS) -> dict[str, int]:
        result: dict[str, int] = self._run(self._core.read_params(tuple(names)))
        return result

    def write_params(self, values: Mapping[str, int]) -> None:
        self._run(self._core.write_params(dict(values)))

    def read_id(self) -> int:
        return int(self._run(self._core.read_id()))

    def assign_id(self, new_id: int) -> None:
        self._run(self._core.assign_id(new_id))

    def ping(self, timeout: float = 0.05) -> bool:
        return bool(self._run(self._core.ping(timeout)))

    def sibling(self, drive_id: int) -> Axis:
        core: AsyncAxis = self._run(self._core.sibling(drive_id))
        return Axis(core, self._runner, owns_runner=False, call_timeout=self._call_timeout)

    def add_trace(self, hook: AxisTraceHook) -> None:
        """``hook`` runs on the facade's loop thread."""
        self._run(self._core.add_trace(hook))

    def close(self) -> None:
        """Close the axis (the connection too unless this is a sibling); idempotent."""
        if self._runner.stopped:
            return
        try:
            self._run(self._core.close())
        finally:
            if self._owns_runner:
                self._runner.stop()

    def __enter__(self) -> Axis:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Axis {self.protocol} id {self.drive_id}>"
