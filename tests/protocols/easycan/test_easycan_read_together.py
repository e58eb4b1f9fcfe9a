"""Cache frames the socketcand hub read in one TCP read reach the EasyCan node with one
stamp; a loaded simulator reads several cycles' frames at once. Scripted input into
``serve()`` on the hub's drive port, motors stepped in simulated time."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Hashable

from rig import wait_until_async

from servobus.families.yzaim import registers as Y
from servobus.protocols.easycan import codec
from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.protocols.easycan.messages import PositionCacheWrite, WriteRequest
from servobus.protocols.easycan.server import serve
from servobus.sim.socketcand_hub import SocketcandHub
from servobus.sim.wall_clock import RealtimeClock
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.transport.can_bus import CanFrame


def cache_frame(position: int, arrived: float, *, reply: bool = False) -> CanFrame:
    ident, data = codec.encode(PositionCacheWrite(1, position, reply))
    return CanFrame(ident, data, 0.0, False, arrived)


async def test_cache_frames_of_one_tcp_read_are_taken_one_per_cycle() -> None:
    """Five silent cache frames for motor 1 with one hub stamp, then two with another:
    none refused, each taken in its own 2 ms cycle, in order (before: the node judged the
    five as written within one cycle and dropped four, as 1018 of 1375 in a loaded
    ``servobus hal`` run)."""
    motor = YzaimMotor(1)
    motor.write_words(*Y.encode_parameter("sync_control", 1))
    start = motor.position
    network = EasyCanNetwork([motor])
    hub = SocketcandHub()
    port = hub.open_port(gate=True)
    stop = asyncio.Event()
    node = asyncio.create_task(serve(network, port, stop=stop))
    sender = object()
    try:
        for k in range(1, 6):
            port.deliver(cache_frame(start + 10 * k, arrived=100.0), sender)
        await wait_until_async(lambda: network.stats.frames == 5)
        taken = []
        for _ in range(5):
            motor.advance(Y.SYNC_CYCLE_S)
            taken.append(motor.target - start)
        for k in (6, 7):
            port.deliver(cache_frame(start + 10 * k, arrived=100.5), sender)
        await wait_until_async(lambda: network.stats.frames == 7)
        for _ in range(2):
            motor.advance(Y.SYNC_CYCLE_S)
            taken.append(motor.target - start)
        assert taken == [10, 20, 30, 40, 50, 60, 70]
        assert motor.refused_cache == 0 and network.stats.cache_dropped == 0
    finally:
        stop.set()
        await node
        await hub.close()


class LoadedNetwork(EasyCanNetwork):
    """A simulator too busy to keep up: every frame is handled 2.5 ms after it reached the
    bus, and the clock has advanced the motors to that moment meanwhile."""

    clock: RealtimeClock

    def handle_raw(self, arbitration_id: int, data: bytes, now: float | None = None,
                   batch: Hashable | None = None) -> list[tuple[int, bytes]]:
        time.sleep(0.0025)  # blocking on purpose: the load this test is about
        self.clock.sync()
        return super().handle_raw(arbitration_id, data, now, batch)


async def test_frames_of_two_reads_within_one_cycle_are_too_fast_when_handled_late() -> None:
    """Issue 18.3 kept: two 0x301 frames the hub read 0.3 ms apart (two stamps) are within
    one 2 ms cycle, so the second is refused (5.5 error 0x05), although the loaded node
    handles each after the tick of that cycle; a third read a cycle later is accepted."""
    motor = YzaimMotor(1)
    network = LoadedNetwork([motor])
    network.clock = RealtimeClock(network.motors)
    hub = SocketcandHub()
    port = hub.open_port(gate=True)
    stop = asyncio.Event()
    node = asyncio.create_task(serve(network, port, clock=network.clock, stop=stop))
    sender = object()
    t0 = time.monotonic()  # the sync signal restarts the 2 ms time base here
    ident, data = codec.encode(WriteRequest(1, Y.BY_NAME["sync_control"].address, (1,)))
    try:
        port.deliver(CanFrame(ident, data, 0.0, False, t0), sender)
        here = motor.position
        port.deliver(cache_frame(here, t0 + 0.0003, reply=True), sender)
        port.deliver(cache_frame(here, t0 + 0.0006, reply=True), sender)
        port.deliver(cache_frame(here, t0 + 0.0023, reply=True), sender)
        await wait_until_async(lambda: network.stats.frames == 4)
        assert motor.refused_cache == 1 and network.stats.errors == 1
        assert network.stats.replies == 4  # the write, two positions and one 0x05
    finally:
        stop.set()
        await node
        await hub.close()
