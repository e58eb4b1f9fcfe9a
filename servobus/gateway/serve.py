"""``servobus serve``: one process owns the machine's links and serves them over OPC UA,
MQTT and (optionally) the web GUI until told to stop.

Order of events: open the machine (links that cannot be opened yet stay offline and are
retried by the machine), start sampling, start the OPC UA server, then MQTT; print one
``servobus serve: ...`` line per front end and ``ready``. When the gateway owns its process
(``own_process``, as ``servobus serve`` runs it) the start-up heap is frozen out of the
garbage collector's scans before "ready" (servobus.gateway.heap: a full collection over
asyncua's address space stalled the loop for 170-265 ms). On SIGINT/SIGTERM (or when a part
fails) every axis is stopped first (``AsyncMachine.stop_all``, the shared halt), then the
front ends and the links close; the MQTT status becomes "offline".
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from servobus.errors import InvalidValue
from servobus.gateway.commands import Commander
from servobus.gateway.heap import freeze_startup_heap
from servobus.gateway.opcua_server import OpcUaGateway, OpcUaOptions
from servobus.gateway.sampler import DEFAULT_RATE_HZ, Sampler
from servobus.gateway.source import Machine

if TYPE_CHECKING:  # MQTT is imported only when it is served (docs/gateway.md "Start-up time")
    from servobus.gateway.mqtt import MqttGateway, MqttOptions

log = logging.getLogger(__name__)
Say = Callable[[str], None]
#: At most this long a start waits for the first samples before it says "ready".
FIRST_ROUND_S = 5.0


@dataclass(frozen=True)
class GatewayOptions:
    opcua: OpcUaOptions
    mqtt: MqttOptions | None = None
    rate_hz: float = DEFAULT_RATE_HZ
    gui_port: int | None = None  # serve the web GUI too (servobus.gateway.gui_bridge)
    #: the gateway owns its process (``servobus serve``): freeze the start-up heap
    own_process: bool = False
    #: a Sparkplug B group id: be an edge node on the ``mqtt`` broker too
    sparkplug: str | None = None


class Gateway:
    """The running parts around one machine; :meth:`start` then :meth:`close`."""

    def __init__(self, machine: Machine, options: GatewayOptions, source: str = "") -> None:
        self.machine = machine
        self.options = options
        self.sampler = Sampler(machine, options.rate_hz)
        self.commander = Commander(machine)
        self.opcua = OpcUaGateway(machine, self.commander, options.opcua, source,
                                  options.rate_hz)
        self.sampler.listeners.append(self.opcua.on_sample)
        self.sampler.link_listeners.append(self.opcua.on_link)
        self.mqtt: MqttGateway | None = None
        if options.mqtt is not None:
            from servobus.gateway.mqtt import MqttGateway

            self.mqtt = MqttGateway(machine, self.sampler, self.commander, options.mqtt)
        self.sparkplug = None
        if options.sparkplug is not None:
            if options.mqtt is None:
                raise InvalidValue("Sparkplug B needs the broker: give --mqtt too")
            from servobus.gateway.sparkplug.node import SparkplugNode

            self.sparkplug = SparkplugNode(machine, self.sampler, self.commander, options.mqtt,
                                           options.sparkplug)
        self.tasks: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        await self.opcua.start()
        self.tasks = [asyncio.create_task(self.sampler.run(), name="gateway-sampler"),
                      asyncio.create_task(self.opcua.run_updates(), name="gateway-opcua")]
        if self.mqtt is not None:
            self.tasks.append(asyncio.create_task(self.mqtt.run(), name="gateway-mqtt"))
        if self.sparkplug is not None:
            self.tasks.append(asyncio.create_task(self.sparkplug.run(),
                                                  name="gateway-sparkplug"))
        # "ready" means values to read: every link's first round (good or Bad) is in
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(FIRST_ROUND_S):
                await self.sampler.first_round.wait()
        if self.options.own_process:
            frozen = freeze_startup_heap()
            log.info("start-up heap frozen: %d objects out of the collector's scans", frozen)

    async def wait_failed(self) -> None:
        """Returns (raising its error) when a part stops by itself."""
        done, _ = await asyncio.wait(self.tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in done:
            task.result()

    async def close(self) -> None:
        """Stop every axis first, whatever else fails; then the servers."""
        try:
            await self.machine.stop_all()
        finally:
            for task in self.tasks:
                task.cancel()
            await asyncio.gather(*self.tasks, return_exceptions=True)
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self.opcua.stop(), 5.0)


def exposure_warning(opcua: OpcUaGateway, mqtt: MqttGateway | None) -> list[str]:
    lines = []
    if not opcua.loopback:
        lines.append(f"warning: OPC UA on {opcua.host}: every axis's state is readable by "
                     "anyone who trusts the server certificate and reaches this address; users "
                     "of the users file can move, stop and power the axes "
                     "(Sign&Encrypt only)")
    if mqtt is not None and mqtt.options.commands:
        lines.append(f"warning: MQTT commands on: whoever the broker {mqtt.broker.host} lets "
                     f"publish to {mqtt.base}/+/cmd can move the axes")
    return lines


async def serve_machine(machine: Machine, options: GatewayOptions, say: Say,
                        source: str = "") -> str:
    """Serve until SIGINT/SIGTERM; returns the signal's name. The machine is closed."""
    stop = asyncio.Event()
    received: list[str] = []
    loop = asyncio.get_running_loop()

    def on_signal(sig: signal.Signals) -> None:
        received.append(sig.name)
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, sig)
    gateway = Gateway(machine, options, source)
    gui = None
    try:
        await gateway.start()
        if options.gui_port is not None:
            from servobus.gateway.gui_bridge import start_gui

            gui = await start_gui(machine, options.gui_port, say)
            if options.own_process:
                freeze_startup_heap()  # the GUI's start-up objects too
        for line in exposure_warning(gateway.opcua, gateway.mqtt):
            say(line)
        say(f"servobus serve: machine {machine.name} ({source}); axes "
            f"{', '.join(machine.axes)}; sampling {options.rate_hz:g} Hz per link at most")
        users = gateway.opcua.options.users
        say(f"servobus serve: opcua {gateway.opcua.endpoint}"
            + ("" if users is not None and len(users)
               else " (read-only: no --users)" if users is None
               else " (read-only: the --users file names no user)"))
        if gateway.mqtt is not None:
            say(f"servobus serve: mqtt {gateway.mqtt.broker.host}:{gateway.mqtt.broker.port} "
                f"topics {gateway.mqtt.base}/... client id {gateway.mqtt.presence.client_id}")
        if gateway.sparkplug is not None:
            spb = gateway.sparkplug
            say(f"servobus serve: sparkplug {spb.topic('NBIRTH')} (devices: the axes) "
                f"client id {spb.client_id}")
        say("servobus serve: ready. Ctrl-C stops every axis and the gateway.")
        waiter = asyncio.create_task(stop.wait())
        failed = asyncio.create_task(gateway.wait_failed())
        await asyncio.wait([waiter, failed], return_when=asyncio.FIRST_COMPLETED)
        waiter.cancel()
        if failed.done():
            failed.result()
        failed.cancel()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        try:
            await gateway.close()
        finally:
            if gui is not None:
                await gui.close()
            await machine.close()
    return received[0] if received else "SIGTERM"


async def open_and_serve(path: Path | None, options: GatewayOptions, say: Say) -> str:
    from servobus.machine import open_machine_async

    if options.mqtt is not None:  # a live gateway on these topics: refuse before any link opens
        from servobus.gateway.mqtt import check_topics_free

        await check_topics_free(options.mqtt, machine_name(path))
    machine = await open_machine_async(path, retry=True)
    source = str(path) if path is not None else "built-in virtual machine"
    return await serve_machine(machine, options, say, source)


def machine_name(path: Path | None) -> str:
    """The machine's name from its file (or the built-in machine's), nothing opened."""
    from servobus.machine.builtin import builtin_spec
    from servobus.machine.config import load_machine_file

    return (builtin_spec() if path is None else load_machine_file(path)).name
