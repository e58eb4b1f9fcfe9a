"""``servobus serve --gui``: the web GUI on the machine's own axes, in the gateway's process.

One process owns each link, so the GUI cannot open the machine's links again; it is handed
the open machine instead (every axis, keyed by its place in the file, in its own unit, as
``servobus gui --machine``). The GUI moves axes in counts past the machine API, so the
machine's limit guard (``guard_limits``) watches the limited axes. The GUI serves
127.0.0.1 only (a person at the gateway PC, no token); closing it leaves the machine to the
gateway, which stops and closes it.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass

import uvicorn

from servobus.errors import ArgumentRangeError
from servobus.gateway.source import Machine
from servobus.gui.app import create_app
from servobus.gui.fleet import AxisHandle, Fleet
from servobus.gui.server import bind, page_url
from servobus.gui.traffic import TrafficLog


class MachineFleet(Fleet):
    """The GUI's fleet over a machine the gateway owns: closing it closes nothing."""

    async def close(self) -> None:
        return None


async def machine_fleet(machine: Machine) -> MachineFleet:
    from servobus.machine import AsyncMachine

    if not isinstance(machine, AsyncMachine):
        raise ArgumentRangeError("--gui needs a machine opened by servobus.machine")
    traffic = TrafficLog()
    for link in machine.links:  # siblings share their owner's trace
        if link.owner is not None:
            await link.owner.add_trace(traffic.hook_for(link.owner))
    machine.guard_limits()
    handles = [AxisHandle(None, key=i, machine_axis=a)
               for i, a in enumerate(machine.axes.values(), start=1)]
    return MachineFleet(machine.source, handles, traffic, machine)


@dataclass
class RunningGui:
    server: uvicorn.Server
    task: asyncio.Task[None]

    async def close(self) -> None:
        self.server.should_exit = True
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.task, 5.0)


async def start_gui(machine: Machine, port: int, say: Callable[[str], None]) -> RunningGui:
    fleet = await machine_fleet(machine)
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
    say(f"servobus serve: gui {page_url('127.0.0.1', sock.getsockname()[1], None)} "
        f"axes {', '.join(machine.axes)}")
    return RunningGui(server, task)

