"""``servobus serve --gui``: the web GUI on the machine's own axes, in the gateway's process.

One process owns each link, so the GUI cannot open the machine's links again; it is handed
the machine's Axis objects instead. Limitation (the GUI is keyed by drive id, one
connection): axes whose drive id is already taken by an earlier axis of the machine (the
same id on another link) are left out, and a line says so. The GUI moves axes in counts,
past the machine API: the machine's limit guard (``guard_limits``) watches the limited axes
while it runs. The GUI serves 127.0.0.1 only
(a person at the gateway PC; no token); its STOP and shutdown stop only its axes, and
closing it leaves the links to the machine.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass

import uvicorn

from servobus.gateway.source import Machine
from servobus.gui.app import create_app
from servobus.gui.fleet import AxisHandle, Fleet
from servobus.gui.server import bind, page_url
from servobus.gui.traffic import TrafficLog


class MachineFleet(Fleet):
    """A Fleet over axes the machine owns: closing it closes nothing."""

    async def close(self) -> None:
        return None


async def machine_fleet(machine: Machine) -> tuple[MachineFleet, list[str]]:
    handles: list[AxisHandle] = []
    left_out: list[str] = []
    traced: set[str] = set()
    traffic = TrafficLog()
    for name, axis in machine.axes.items():
        core = axis.axis
        if core is None or any(h.id == core.drive_id for h in handles):
            left_out.append(name)
            continue
        if axis.url not in traced:
            traced.add(axis.url)
            await core.add_trace(traffic.hook)
        handles.append(AxisHandle(core))
    return MachineFleet(f"machine {machine.name}", handles, traffic), left_out


@dataclass
class RunningGui:
    server: uvicorn.Server
    task: asyncio.Task[None]

    async def close(self) -> None:
        self.server.should_exit = True
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.task, 5.0)


async def start_gui(machine: Machine, port: int, say: Callable[[str], None]) -> RunningGui:
    guard = getattr(machine, "guard_limits", None)
    if guard is not None:  # the GUI jogs and waves past the machine API: watch the limits
        guard()
    fleet, left_out = await machine_fleet(machine)
    sock = bind("127.0.0.1", port)
    app = create_app(fleet=fleet)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="on",
                                           access_log=False, ws_per_message_deflate=False))
    # the gateway handles SIGINT/SIGTERM (stop every axis first); uvicorn must not take them
    server.capture_signals = contextlib.nullcontext  # type: ignore[method-assign,assignment]
    task = asyncio.create_task(server.serve(sockets=[sock]), name="gateway-gui")
    while not server.started and not task.done():
        await asyncio.sleep(0.02)
    if task.done():
        task.result()
    names = {h.axis.drive_id: n for n, a in machine.axes.items() for h in fleet.handles.values()
             if a.axis is h.axis}
    shown = ", ".join(f"{names[i]} (id {i})" for i in fleet.handles)
    say(f"servobus serve: gui {page_url('127.0.0.1', sock.getsockname()[1], None)} axes {shown}"
        + (f"; left out (drive id taken): {', '.join(left_out)}" if left_out else ""))
    return RunningGui(server, task)

