"""What the GUI server holds while it runs (one per app): the fleet and its services."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from servobus.axis.base import AsyncAxis
from servobus.axis.halt import halt
from servobus.gui.autotune import AutoTune
from servobus.gui.fleet import Fleet
from servobus.gui.jog import JogControl
from servobus.gui.monitor import StatusMonitor
from servobus.gui.sampler import AxisSampler
from servobus.gui.tuning import TuningState

if TYPE_CHECKING:
    from servobus.gui.scope_session import ScopeSession

log = logging.getLogger(__name__)


@dataclass
class GuiState:
    fleet: Fleet
    monitor: StatusMonitor
    jog: JogControl
    samplers: dict[int, AxisSampler]
    tuning: dict[int, TuningState]
    autotune: AutoTune
    sessions: set[ScopeSession] = field(default_factory=set)
    #: What the shutdown's stop gave per axis (None: stopped); None before the shutdown.
    halted: dict[int, BaseException | None] | None = None
    _closed: bool = False

    @classmethod
    def build(cls, fleet: Fleet, jog_lease_s: float) -> GuiState:
        return cls(fleet=fleet, monitor=StatusMonitor(fleet),
                   jog=JogControl(fleet, jog_lease_s),
                   samplers={i: AxisSampler(h) for i, h in fleet.handles.items()},
                   tuning={i: TuningState() for i in fleet.handles},
                   autotune=AutoTune(jog_lease_s))

    @property
    def closed(self) -> bool:
        """The shutdown has begun (servobus.gui.server checks it after a forced exit)."""
        return self._closed

    def start(self) -> None:
        self.monitor.start()
        self.jog.start()

    async def _halt(self) -> dict[int, BaseException | None]:
        """Every axis stopped at once (servobus.axis.halt). A machine axis's stop ends its
        lease first, whoever holds it (no target update follows the stop); each stop is
        counted on its handle like every other call of the GUI."""
        handles = self.fleet.handles
        axes = {i: h.axis for i, h in handles.items()}
        by_axis = {id(a): handles[i] for i, a in axes.items()}

        async def stop(axis: AsyncAxis, timeout_s: float) -> None:
            handle = by_axis[id(axis)]
            m = handle.machine_axis
            await handle.call(asyncio.wait_for(axis.stop() if m is None else m.stop(),
                                               timeout_s))

        return await halt(axes, stop=stop)

    async def stop_all(self) -> dict[int, str]:
        """STOP: every axis ramps down and holds (all at once); '' or the error per axis.
        Every lease ends, and a page still renewing is refused (servobus.gui.jog)."""
        results = await self._halt()
        return {i: "" if r is None else f"{type(r).__name__}: {r}" for i, r in results.items()}

    async def shut_down(self) -> None:
        """The GUI is going away: stop every axis first, then the services, the link last.

        The stop (servobus.axis.halt) comes before anything else and nothing can skip it:
        it never raises for an axis and finishes under cancellation; every lease (jog,
        constant speed) ends with it and new ones are refused from the moment it starts;
        drive-generated waves stop with it. Then each service stops in its own try (a
        sampler that died with an exception is logged, the others still stop) and the
        fleet closes last,
        whatever happened before. A second call does nothing.
        """
        if self._closed:
            return
        self._closed = True
        self.jog.close()  # no page can start a jog from here on
        self.autotune.closed = True  # nor an auto-tune run
        try:
            self.halted = await self._halt()
        finally:
            steps: list[tuple[str, Callable[[], Awaitable[None]]]] = [
                ("page motions", self.jog.stop), ("auto-tune runs", self.autotune.stop),
                ("status monitor", self.monitor.stop),
                *((f"sampler of axis {i}", s.stop) for i, s in self.samplers.items()),
                ("connection", self.fleet.close)]
            await _each(steps)


async def _each(steps: list[tuple[str, Callable[[], Awaitable[None]]]]) -> None:
    """Run every step, each in its own try; a cancellation is passed on after the last."""
    cancelled: asyncio.CancelledError | None = None
    for name, step in steps:
        try:
            await step()
        except asyncio.CancelledError as exc:
            cancelled = exc
        except Exception as exc:  # logged, and the next step still runs
            log.error("GUI shutdown: %s failed: %s: %s", name, type(exc).__name__, exc)
    if cancelled is not None:
        raise cancelled
