"""The component's end as LinuxCNC's shutdown plays it, in-process: the joint's enable falls
(the sync group's stream ends and the group stops its motor), and SIGTERM comes while that
stop is still under way (the runner is cancelled, then every position axis is stopped, as
servobus.hal.component.serve does). One stop runs after the other, never interleaved: the
motor is never in speed mode at a speed above 0 and rests where the program left it (a CI
run of the rotary example found the motor 4.6 deg past A135 after such an end: docs/linuxcnc.md,
"When LinuxCNC stops feeding the component")."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from bridge_rig import blank_pins
from rig import wait_until_async

from servobus.hal.bridge import Bridge
from servobus.machine import AsyncMachine, open_machine_async
from servobus.protocols.easycan.messages import WriteRequest
from servobus.transport.base import Direction

TARGET_SPEED, SPECIAL_FUNCTION, SPEED_MODE = 0x02, 0x19, 3

TABLE = """\
[axes.a]
url = "sim://easycan?fast=1&timeout=0.5"  # a loaded host: replies late, never lost
id = 1
unit = "deg"
speed = 1800.0
accel = 36000.0
hal = "position"
"""


@pytest.fixture
async def machine(tmp_path: Path) -> AsyncIterator[AsyncMachine]:
    path = tmp_path / "table.toml"
    path.write_text(TABLE)
    m = await open_machine_async(path)
    try:
        yield m
    finally:
        await m.close()


class Registers:
    """0x02 and 0x19 as the host's writes leave them, and what those writes did: ``turned``
    when 0x19 = 3 (speed mode) went out while 0x02 held a speed above 0; ``stops``, the
    writes of the stop sequences in order."""

    def __init__(self) -> None:
        self.speed: int | None = None
        self.turned: list[int] = []
        self.writes: list[tuple[int, int]] = []

    def __call__(self, direction: Direction, item: object, t: float) -> None:
        if direction is not Direction.TX or not isinstance(item, WriteRequest):
            return
        if item.address == TARGET_SPEED:
            self.speed = item.values[0]
        elif item.address == SPECIAL_FUNCTION and item.values == (SPEED_MODE,) \
                and self.speed:
            self.turned.append(self.speed)
        if item.address in (TARGET_SPEED, SPECIAL_FUNCTION):
            self.writes.append((item.address, item.values[0]))


async def test_sigterm_during_the_groups_stop_waits_for_it(machine: AsyncMachine) -> None:
    pins = blank_pins(["a"])
    registers = Registers()
    await machine["a"].core().add_trace(registers)
    bridge = Bridge([machine["a"]], pins, 60.0)
    runner = asyncio.create_task(bridge.run())
    pins["watchdog"] = True
    await wait_until_async(lambda: not pins["fault"], timeout=30,
                           what="fed, online, no fault")
    pins["a.enable"] = True
    (axis,) = bridge.axes
    await wait_until_async(lambda: axis.streaming, timeout=30, what="streaming")
    x = 0.0
    while x < 45.0:  # the joint's command, 2 ms servo periods at 180 deg/s
        x = min(x + 0.36, 45.0)
        pins["a.position-cmd"] = x
        await asyncio.sleep(0.002)  # a producer's period, not a wait for an outcome
    await wait_until_async(lambda: abs(float(pins["a.position-fb"]) - 45.0) < 0.05,
                           timeout=20, what="the motor at 45 deg")

    shutdown: list[asyncio.Task[None]] = []

    async def sigterm() -> None:  # servobus.hal.component.serve's order
        runner.cancel()
        with pytest.raises(asyncio.CancelledError):
            await runner
        await bridge.stop()

    def on_first_stop_write(direction: Direction, item: object, t: float) -> None:
        if (not shutdown and direction is Direction.TX and isinstance(item, WriteRequest)
                and item.address == TARGET_SPEED and item.values == (0,)):
            shutdown.append(asyncio.get_running_loop().create_task(sigterm()))

    await machine["a"].core().add_trace(on_first_stop_write)
    start = len(registers.writes)
    pins["a.enable"] = False  # LinuxCNC's task halts: the group stops the motor
    await wait_until_async(lambda: bool(shutdown), timeout=30, what="the group's stop began")
    await shutdown[0]

    assert registers.turned == [], registers.writes[start:]
    stops = registers.writes[start:]
    sequence = [(TARGET_SPEED, 0), (SPECIAL_FUNCTION, SPEED_MODE), (SPECIAL_FUNCTION, 0),
                (TARGET_SPEED, stops[-1][1])]
    assert stops and len(stops) % 4 == 0, stops
    assert all(stops[i:i + 4] == sequence for i in range(0, len(stops), 4)), stops
    assert abs(await machine["a"].position() - 45.0) < 0.05
