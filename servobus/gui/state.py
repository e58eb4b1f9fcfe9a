"""What the GUI server holds while it runs (one per app): the fleet and its services."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from servobus.errors import ServobusError
from servobus.gui.fleet import Fleet
from servobus.gui.jog import JogControl
from servobus.gui.monitor import StatusMonitor
from servobus.gui.sampler import AxisSampler
from servobus.gui.tuning import TuningState

if TYPE_CHECKING:
    from servobus.gui.scope_session import ScopeSession


@dataclass
class GuiState:
    fleet: Fleet
    monitor: StatusMonitor
    jog: JogControl
    samplers: dict[int, AxisSampler]
    tuning: dict[int, TuningState]
    sessions: set[ScopeSession] = field(default_factory=set)

    @classmethod
    def build(cls, fleet: Fleet, jog_lease_s: float) -> GuiState:
        return cls(fleet=fleet, monitor=StatusMonitor(fleet),
                   jog=JogControl(fleet, jog_lease_s),
                   samplers={i: AxisSampler(h) for i, h in fleet.handles.items()},
                   tuning={i: TuningState() for i in fleet.handles})

    def start(self) -> None:
        self.monitor.start()
        self.jog.start()

    async def stop_all(self) -> dict[int, str]:
        """STOP: every axis ramps down and holds (all at once); '' or the error per axis."""
        self.jog.forget()
        handles = list(self.fleet.handles.values())
        results = await asyncio.gather(*(h.call(h.axis.stop()) for h in handles),
                                       return_exceptions=True)
        out: dict[int, str] = {}
        for h, r in zip(handles, results, strict=True):
            if isinstance(r, BaseException) and not isinstance(r, ServobusError):
                raise r
            out[h.id] = "" if not isinstance(r, BaseException) else f"{type(r).__name__}: {r}"
        return out

    async def shut_down(self) -> None:
        """Stop the services, stop every axis (the GUI is going away), close the link."""
        await self.jog.stop()
        await self.monitor.stop()
        for sampler in self.samplers.values():
            await sampler.stop()
        try:
            await self.stop_all()
        finally:
            await self.fleet.close()
