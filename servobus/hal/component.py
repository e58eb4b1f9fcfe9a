"""``servobus hal``'s process: the HAL component around :class:`~servobus.hal.bridge.Bridge`.

Order (docs/linuxcnc.md): the machine file is checked first (a mistake is one line before
HAL is touched), then the pins are made, then the links open (an axis whose link does not
open starts offline, its ``fault`` set, and comes online when the link does), then the
component is ready (``loadusr -W`` waits for that: the next HAL line finds the axes
online). SIGTERM (``halrun``'s unload, the
end of LinuxCNC), SIGINT or SIGHUP (the terminal LinuxCNC was started from closes while the
component runs) stops every position axis, then closes the machine without stopping the
monitor axes (step/dir from elsewhere drives them).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
from pathlib import Path
from types import ModuleType
from typing import Any

from servobus.hal.bridge import Bridge
from servobus.hal.pins import AXIS_PINS, COMPONENT_PINS, Pin, Pins, axis_pin
from servobus.machine.config import MachineSpec, load_machine_file
from servobus.machine.machine import open_machine_async

log = logging.getLogger(__name__)

#: Each stops every position axis, then ends the component (SIGHUP's default would kill it
#: without stopping a motor that streams).
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)


def make_pins(hal: ModuleType, name: str, spec: MachineSpec) -> Any:
    """The component with every pin (``hal.component``), not yet ready."""
    component = hal.component(name)
    for pin in COMPONENT_PINS:
        _new_pin(hal, component, pin.name, pin)
    for axis in spec.axes:
        for pin in AXIS_PINS:
            _new_pin(hal, component, axis_pin(axis.name, pin.name), pin)
        component[axis_pin(axis.name, "fault")] = True  # until the first cycle says otherwise
    component["fault"] = True
    return component


def _new_pin(hal: ModuleType, component: Any, name: str, pin: Pin) -> None:
    kind = {"float": hal.HAL_FLOAT, "bit": hal.HAL_BIT, "s32": hal.HAL_S32}[pin.kind]
    direction = hal.HAL_IN if pin.direction == "in" else hal.HAL_OUT
    component.newpin(name, kind, direction)


async def serve(hal: ModuleType, machine_path: Path, name: str, watchdog_s: float) -> str:
    """Run the component until SIGTERM, SIGINT or SIGHUP; returns the signal's name."""
    spec = load_machine_file(machine_path)
    component = make_pins(hal, name, spec)
    pins: Pins = component
    stopped = asyncio.Event()
    caught: list[str] = []
    loop = asyncio.get_running_loop()

    def on_signal(sig: signal.Signals) -> None:
        caught.append(sig.name)
        stopped.set()

    for sig in STOP_SIGNALS:
        loop.add_signal_handler(sig, on_signal, sig)
    try:
        machine = await open_machine_async(machine_path, retry=True)
        try:
            bridge = Bridge([machine[a.name] for a in spec.axes], pins, watchdog_s)
            component.ready()  # loadusr -W goes on once the links were tried
            runner = asyncio.create_task(bridge.run(), name="hal bridge")
            waiter = asyncio.create_task(stopped.wait())
            await asyncio.wait({runner, waiter}, return_when=asyncio.FIRST_COMPLETED)
            runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await runner
            await bridge.stop()
            log.info("every position axis stopped")
        finally:
            await machine.close(stop=False)
    finally:
        component.exit()
    return caught[0] if caught else "end"
