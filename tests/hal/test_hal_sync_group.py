"""The component's sync groups on in-process virtual drives (docs/linuxcnc.md, "Sync
groups"): two YZ-AIM EasyCan position axes on one bus stream as one group (one cache frame
per motor per cycle, one synchronisation signal for both), start together, and a fault on
one stops both."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from bridge_rig import blank_pins, cycles, stopped
from rig import wait_until_async

from servobus.hal.bridge import AxisBridge, Bridge
from servobus.hal.pins import Pins
from servobus.machine import AsyncMachine, open_machine_async
from servobus.protocols.easycan.messages import PositionCacheWrite, WriteRequest
from servobus.transport.base import Direction

SYNC_CONTROL = 0x1C  # YZ-AIM manual 5.2: a write of 1 is the synchronisation signal

# timeout=1: the virtual motors answer on this test's own event loop, so a host stall
# between a request and its reply counts against the client's per-attempt deadline (50 ms
# by default, made for a real bus). Under a full suite on two cores that stall passed 50 ms:
# the group's synchronisation signal (sync_control = 1, sent once, never re-sent) "got no
# reply", both axes faulted and the group never streamed ("streaming not met"). The
# deadline of the drives' replies is not what these tests prove.
BUS = """\
[axes.c]
url = "sim://easycan?fast=1&timeout=1"
id = 1
unit = "deg"
speed = 360.0
accel = 3600.0
hal = "position"

[axes.d]
url = "sim://easycan?fast=1&timeout=1"
id = 2
unit = "deg"
speed = 360.0
accel = 3600.0
hal = "position"
"""


@pytest.fixture
async def machine(tmp_path: Path) -> AsyncIterator[AsyncMachine]:
    path = tmp_path / "bus.toml"
    path.write_text(BUS)
    m = await open_machine_async(path)
    try:
        yield m
    finally:
        await m.close()


class BusLog:
    """What the host sends on the bus: ``c`` a cache frame of motor 1 or 2, ``S`` a sync
    signal (0x1C = 1) to motor 1 or 2, in order."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, int]] = []

    def __call__(self, direction: Direction, item: object, t: float) -> None:
        if direction is not Direction.TX:
            return
        if isinstance(item, PositionCacheWrite):
            self.sent.append(("c", item.slave))
        elif isinstance(item, WriteRequest) and item.address == SYNC_CONTROL \
                and item.values == (1,):
            self.sent.append(("S", item.slave))

    def count(self, kind: str, slave: int) -> int:
        return self.sent.count((kind, slave))


async def streaming(bus: BusLog, c: AxisBridge, d: AxisBridge) -> None:
    """Until motor 2 has taken more than 10 cache frames; a fault of the group fails at
    once, with its reason, instead of at the deadline."""
    await wait_until_async(lambda: bus.count("c", 2) > 10 or c.latched or d.latched,
                           timeout=30, what="streaming")
    assert (c.latched, d.latched) == (None, None)


async def ramp_both(pins: Pins, to: float, speed: float) -> None:
    """c and d's position-cmd together, one step of ``speed`` x 2 ms per servo period."""
    x = float(pins["c.position-cmd"])
    while x < to:
        x = min(x + speed * 0.002, to)
        pins["c.position-cmd"] = pins["d.position-cmd"] = x
        await asyncio.sleep(0.002)  # the joints' servo period (a producer, no wait)


async def started(machine: AsyncMachine,
                  ) -> tuple[Bridge, Pins, BusLog, asyncio.Task[None]]:
    pins = blank_pins(["c", "d"])
    bus = BusLog()
    await machine["c"].core().add_trace(bus)  # one client: the bus's frames, both motors
    bridge = Bridge([machine["c"], machine["d"]], pins, 60.0)
    task = asyncio.create_task(bridge.run())
    pins["watchdog"] = True
    await wait_until_async(lambda: not pins["fault"], what="fed, online, no fault")
    return bridge, pins, bus, task


async def test_two_axes_of_one_bus_stream_as_one_group(machine: AsyncMachine) -> None:
    assert machine["c"].cyclic_group() is machine["d"].cyclic_group() is not None
    bridge, pins, bus, task = await started(machine)
    c, d = bridge.axes
    try:
        pins["c.enable"] = True  # alone: the group waits for d
        await wait_until_async(lambda: c.streaming, what="c enabled")
        await cycles(c, 10)
        assert bus.count("S", 1) == 0 and bus.count("c", 1) == 0
        pins["d.enable"] = True  # both enabled: one signal, then both caches every cycle
        # a generous deadline: on a loaded machine the stream skips the cycles it would
        # send late (servobus.protocols.easycan.sync) and the host stalls
        await streaming(bus, c, d)
        await ramp_both(pins, 45.0, 180.0)
        await wait_until_async(
            lambda: all(abs(float(pins[f"{a}.position-fb"]) - 45.0) < 0.5 for a in "cd"),
            timeout=20, what="both at 45 deg")
        pins["c.enable"] = False  # c alone disabled: the group stops, d too (no fault)
        await wait_until_async(lambda: c.cyclic_stats is not None and not d.streaming,
                               what="the group stopped")
        assert not pins["c.fault"] and not pins["d.fault"]  # disabled is no fault
        sent = len(bus.sent)
        pins["d.position-cmd"] = 45.5  # d still enabled, never resumes by itself
        await cycles(d, 10)
        assert len(bus.sent) == sent
    finally:
        await stopped(task)
    stats = c.cyclic_stats
    assert stats is not None and d.cyclic_stats is stats and stats.cycles > 50
    assert stats.frames == 2 * stats.cycles  # one cache frame per motor per cycle
    # one synchronisation signal for the group: 0x1C = 1 to each motor back to back
    # (concurrent writes: either first), once
    signals = [i for i, (kind, _) in enumerate(bus.sent) if kind == "S"]
    assert sorted(bus.sent[i] for i in signals) == [("S", 1), ("S", 2)]
    assert signals[1] == signals[0] + 1
    caches = [slave for kind, slave in bus.sent[signals[1] + 1:] if kind == "c"]
    assert caches == [1, 2] * (len(caches) // 2)  # each cycle: motor 1, motor 2
    assert len(caches) >= 2 * stats.cycles
    for axis in "cd":
        assert abs(await machine[axis].position() - 45.0) < 0.5


async def test_a_fault_on_one_axis_stops_the_whole_group(machine: AsyncMachine) -> None:
    bridge, pins, bus, task = await started(machine)
    c, d = bridge.axes
    try:
        pins["c.enable"] = pins["d.enable"] = True
        # a generous deadline: on a loaded machine the stream skips the cycles it would
        # send late (servobus.protocols.easycan.sync) and the host stalls
        await streaming(bus, c, d)
        await ramp_both(pins, 10.0, 180.0)
        pins["d.position-cmd"] = 180.0  # half a turn at once on d: refused, d faults
        await wait_until_async(lambda: pins["c.fault"] and pins["d.fault"],
                               what="both faulted")
        assert d.latched is not None and "refused" in d.latched
        assert c.latched is not None and "sync group" in c.latched
        await wait_until_async(lambda: not c.streaming and not d.streaming
                               and c.cyclic_stats is not None, what="the group stopped")
        await wait_until_async(lambda: not pins["c.moving"] and not pins["d.moving"],
                               timeout=20, what="both at rest")
        sent = len(bus.sent)
        pins["c.position-cmd"] = 11.0  # a stopped axis never resumes by itself
        await cycles(c, 10)
        assert len(bus.sent) == sent
        for axis in "cd":
            assert abs(await machine[axis].position() - 10.0) < 1.0
    finally:
        await stopped(task)
