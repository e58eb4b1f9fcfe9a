"""The component's loop on in-process virtual drives, its pins a dict (no LinuxCNC): the
position stream, the refused step, fault-reset, the watchdog, monitor axes left alone."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from bridge_rig import blank_pins, cycles, stopped
from rig import wait_until_async

from servobus.hal.bridge import Bridge
from servobus.hal.pins import Pins
from servobus.machine import AsyncMachine, open_machine_async

CELL = """\
[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
speed = 360.0
accel = 3600.0
hal = "position"

[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0

[axes.y]
url = "sim://dyn232?fast=1"
id = 2
unit = "mm"
per_rev = 5.0
limits = [-1.0, 1.0]
speed = 1000.0
accel = 1000000.0
hal = "position"
"""


@pytest.fixture
async def machine(tmp_path: Path) -> AsyncIterator[AsyncMachine]:
    path = tmp_path / "cell.toml"
    path.write_text(CELL)
    m = await open_machine_async(path)
    try:
        yield m
    finally:
        await m.close()


async def running(machine: AsyncMachine, pins: Pins, watchdog_s: float = 60.0,
                  ) -> tuple[Bridge, asyncio.Task[None]]:
    bridge = Bridge([machine["c"], machine["x"]], pins, watchdog_s)
    task = asyncio.create_task(bridge.run())
    assert pins["fault"] or not bridge.axes[0].cycles  # not fed yet: faulted
    pins["watchdog"] = True  # fed once (LinuxCNC's threads started)
    await wait_until_async(lambda: not pins["fault"], what="fed, online, no fault")
    return bridge, task


async def ramp(pins: Pins, to: float, speed: float) -> None:
    """position-cmd from where it stands to ``to``, one step of ``speed`` x 2 ms per servo
    period of a LinuxCNC joint (a stalled loop slows the ramp down, never steps it)."""
    x = float(pins["c.position-cmd"])
    while x < to:
        x = min(x + speed * 0.002, to)
        pins["c.position-cmd"] = x
        await asyncio.sleep(0.002)  # the joint's servo period (a producer, no wait)


async def test_a_position_axis_follows_its_command(machine: AsyncMachine) -> None:
    pins = blank_pins(["c", "x"])
    _, task = await running(machine, pins)
    try:
        await wait_until_async(lambda: pins["c.online"] and pins["x.online"], what="online")
        pins["c.enable"] = True
        await wait_until_async(lambda: pins["c.enabled"], what="servo on")
        await ramp(pins, 90.0, 180.0)
        await wait_until_async(lambda: abs(float(pins["c.position-fb"]) - 90.0) < 0.5,
                               timeout=20, what="position-fb at 90 deg")
        assert abs(await machine["c"].position() - 90.0) < 0.5
        assert not pins["fault"] and not pins["c.fault"]
    finally:
        await stopped(task)


async def test_a_step_beyond_speed_is_refused_and_faults(machine: AsyncMachine) -> None:
    pins = blank_pins(["c", "x"])
    bridge, task = await running(machine, pins)
    try:
        await wait_until_async(lambda: pins["c.online"], what="online")
        pins["c.enable"] = True
        await wait_until_async(lambda: pins["c.enabled"], what="servo on")
        pins["c.position-cmd"] = 180.0  # half a turn at once: far beyond 360 deg/s
        await wait_until_async(lambda: pins["c.fault"] and pins["fault"], what="fault")
        await wait_until_async(lambda: not pins["c.moving"], what="at rest")
        assert abs(await machine["c"].position()) < 1.0  # nothing was sent
        # position-fb is the drive's position read back, not the command (which says 180)
        await cycles(bridge.axes[0], 2)
        assert abs(float(pins["c.position-fb"]) - await machine["c"].position()) < 0.1
        pins["c.fault-reset"] = True
        await wait_until_async(lambda: not pins["c.fault"] and not pins["fault"],
                               what="fault cleared")
        pins["c.position-cmd"] = 0.5  # a faulted axis never resumes by itself
        await cycles(bridge.axes[0], 10)
        assert abs(await machine["c"].position()) < 0.2
    finally:
        await stopped(task)


async def test_an_unfed_watchdog_faults_every_axis_without_latching(
        machine: AsyncMachine) -> None:
    pins = blank_pins(["c", "x"])
    bridge = Bridge([machine["c"], machine["x"]], pins, 0.05)
    task = asyncio.create_task(bridge.run())
    try:
        await cycles(bridge.axes[0], 50)  # far beyond 0.05 s
        assert pins["fault"] and pins["c.fault"] and pins["x.fault"]
        pins["c.enable"] = True  # refused: an enable edge while faulted streams nothing
        await cycles(bridge.axes[0], 5)
        assert not bridge.axes[0].streaming
        pins["watchdog"] = True
        await wait_until_async(lambda: not pins["fault"], what="fed: no fault, no reset")
        assert bridge.axes[0].latched is None
    finally:
        await stopped(task)


async def test_a_starved_watchdog_stops_position_axes_and_faults_all(
        machine: AsyncMachine) -> None:
    pins = blank_pins(["c", "x"])

    async def feed() -> None:  # LinuxCNC's servo thread toggling the watchdog
        while True:
            pins["watchdog"] = not pins["watchdog"]
            await asyncio.sleep(0.02)  # its clock's half period (a producer, no wait)

    bridge = Bridge([machine["c"], machine["x"]], pins, 0.3)
    task = asyncio.create_task(bridge.run())
    feeder = asyncio.create_task(feed())
    try:
        await wait_until_async(lambda: not pins["fault"], what="fed, online, no fault")
        pins["c.enable"] = True
        await wait_until_async(lambda: bridge.axes[0].streaming, what="streaming")
        await ramp(pins, 30.0, 180.0)
        feeder.cancel()  # LinuxCNC stops feeding: 0.3 s later every axis faults, c stops
        await wait_until_async(lambda: pins["fault"] and pins["x.fault"] and pins["c.fault"],
                               timeout=20, what="watchdog fault")
        assert not bridge.axes[0].streaming
        assert bridge.axes[1].latched is not None and "watchdog" in bridge.axes[1].latched
        feeder = asyncio.create_task(feed())  # toggling again: the fault holds
        await wait_until_async(lambda: not bridge.watchdog.starved, what="fed again")
        await cycles(bridge.axes[0], 5)
        assert pins["c.fault"]
        pins["c.fault-reset"] = pins["x.fault-reset"] = True
        await wait_until_async(lambda: not pins["c.fault"] and not pins["x.fault"],
                               what="cleared")
    finally:
        feeder.cancel()
        await stopped(task)


async def test_a_monitor_axis_is_read_and_never_commanded(machine: AsyncMachine) -> None:
    pins = blank_pins(["c", "x"])
    bridge, task = await running(machine, pins)
    try:
        await wait_until_async(lambda: pins["x.online"], what="online")
        await machine["x"].move_to(10.0)  # step/dir from elsewhere, here the machine API
        await wait_until_async(lambda: abs(float(pins["x.position-fb"]) - 10.0) < 0.01,
                               timeout=20, what="x.position-fb at 10 mm")
        pins["x.position-cmd"] = 50.0  # ignored: monitor mode
        await cycles(bridge.axes[1], 10)
        assert abs(await machine["x"].position() - 10.0) < 0.01
    finally:
        await stopped(task)


async def test_a_command_past_a_soft_limit_is_refused_and_faults(machine: AsyncMachine) -> None:
    pins = blank_pins(["c", "x", "y"])
    bridge = Bridge([machine["c"], machine["x"], machine["y"]], pins, 60.0)
    task = asyncio.create_task(bridge.run())
    try:
        pins["watchdog"] = True
        await wait_until_async(lambda: not pins["fault"], what="fed, online, no fault")
        pins["y.enable"] = True  # y streams target updates (DYN232M)
        await wait_until_async(lambda: bridge.axes[2].streaming, what="streaming")
        x = 0.0
        while not pins["y.fault"] and x < 1.5:  # towards the limit at 1 mm
            x += 0.05
            pins["y.position-cmd"] = x
            await cycles(bridge.axes[2], 1)
        assert pins["y.fault"] and bridge.axes[2].latched is not None
        assert "outside the soft limits" in bridge.axes[2].latched
        assert await machine["y"].position() <= 1.0 + 0.01
    finally:
        await stopped(task)
