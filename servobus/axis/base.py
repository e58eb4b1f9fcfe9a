"""Protocol-agnostic Axis API (AXIS_API.md): the AsyncAxis core and the sync ``Axis`` facade.

Each protocol implements the abstract primitives of :class:`AsyncAxis` once; the logic that
combines them (move with wait, wait_idle, stop, read_params/write_params) lives here once.
:class:`Axis` runs any AsyncAxis on a private event-loop thread with the same method names.
"""

from __future__ import annotations

import asyncio
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from types import TracebackType
from typing import Any

from servobus.axis.sync import LoopThread
from servobus.errors import DriveAlarm, DriveTimeout
from servobus.families.dmm import params as P
from servobus.families.dmm.registers import DriveConfig, DriveStatus
from servobus.transport.base import Direction

#: Client-level trace hook: decoded packets/frames and the errors met (see transport.trace).
AxisTraceHook = Callable[[Direction, object, float], None]

DEFAULT_WAIT_TIMEOUT_S = 30.0


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
        P.spec(name).check(value)

    # ------------------------------------------------------------- shared logic (once)
    async def move_to(self, position: int, *, wait: bool = False,
                      timeout: float | None = None) -> None:
        await self._send_move_to(position)
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def move_by(self, distance: int, *, wait: bool = False,
                      timeout: float | None = None) -> None:
        await self._send_move_by(distance)
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def stop(self) -> None:
        """Constant speed 0: the drive ramps down at Max Accel and holds position."""
        await self.turn(0)

    async def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                        poll: float = 0.02) -> DriveStatus:
        """Poll status until motion is done and the motor is on position.

        Raises DriveAlarm as soon as a latched alarm shows (the checksum notice, code 4, is
        not latched and does not raise), DriveTimeout when ``timeout`` passes.
        """
        deadline = time.monotonic() + timeout
        while True:
            st = await self.status()
            if st.alarm.latching:
                raise DriveAlarm(
                    f"drive {self.drive_id} alarm {st.alarm.name.lower()} "
                    f"(code {int(st.alarm)}); reset() clears it",
                    code=int(st.alarm), drive_id=self.drive_id,
                )
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

    def move_to(self, position: int, *, wait: bool = False,
                timeout: float | None = None) -> None:
        self._run(self._core.move_to(position, wait=wait, timeout=timeout))

    def move_by(self, distance: int, *, wait: bool = False,
                timeout: float | None = None) -> None:
        self._run(self._core.move_by(distance, wait=wait, timeout=timeout))

    def turn(self, rpm: int) -> None:
        self._run(self._core.turn(rpm))

    def stop(self) -> None:
        self._run(self._core.stop())

    def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                  poll: float = 0.02) -> DriveStatus:
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
