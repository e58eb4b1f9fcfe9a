"""DYN CAN client against virtual nodes in-process on python-can's virtual bus."""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Awaitable

import pytest
from dyncan_rig import harness
from rig import wait_until_async

from servobus.axis.base import AsyncAxis
from servobus.errors import ArgumentRangeError, DriveAlarm, DriveError, DriveTimeout
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode, DriveConfig
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan import commands as cmds
from servobus.protocols.dyncan.axis import open_can_axis
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.protocols.dyncan.server import serve
from servobus.sim.dmm.drive import VirtualDrive
from servobus.transport.base import Direction
from servobus.transport.can_bus import AsyncCanBus, parse_can_spec

_channels = itertools.count()  # this module's own virtual channels (see also dyncan_rig)
pytestmark = pytest.mark.timeout(30)


def test_parse_can_spec() -> None:
    assert parse_can_spec("socketcand:127.0.0.1:29536") == {
        "interface": "socketcand", "host": "127.0.0.1", "port": 29536, "channel": "can0"}
    assert parse_can_spec("pcan:PCAN_USBBUS1", bitrate=500000) == {
        "interface": "pcan", "channel": "PCAN_USBBUS1", "bitrate": 500000}
    assert parse_can_spec("slcan:/dev/ttyACM0")["channel"] == "/dev/ttyACM0"
    with pytest.raises(ArgumentRangeError):
        parse_can_spec("nocolon")
    with pytest.raises(ArgumentRangeError):
        parse_can_spec("socketcand:localhost")


async def test_axis_api_reads_and_writes() -> None:
    async with harness(1, 2) as h:
        ax = h.axis(1)
        assert ax.protocol == "dyncan"
        assert await ax.read_id() == 1
        st = await ax.status()
        assert st.in_position and st.enabled
        await ax.write_params({"main_gain": 55, "line_num": 1234, "gear_num": 2048})
        params = await ax.read_params(["main_gain", "speed_gain", "line_num", "gear_num"])
        d = h.network.node(1).drive
        assert params == {"main_gain": 55, "speed_gain": d.get_param("speed_gain"),
                          "line_num": 1234, "gear_num": 2048}
        assert await ax.read_param("gear_num") == 2048
        await ax.write_param("max_speed", 77)
        assert await ax.read_param("max_speed") == 77  # frames are handled in order
        await ax.set_config(DriveConfig(absolute=True))
        assert (await ax.config()).absolute
        assert await ax.echo(b"\x00\x7f\x80\xff") == b"\x00\x7f\x80\xff"
        assert [await ax.counter() for _ in range(3)] == [0, 1, 2]
        await ax.disable()
        assert not (await ax.status()).enabled
        await ax.enable()
        other = await ax.sibling(2)
        assert await other.read_id() == 2
        assert h.network.node(2).drive.get_param("main_gain") != 55


async def test_range_checks_before_sending() -> None:
    async with harness(1) as h:
        ax = h.axis(1)
        await ax.gear_num()  # counts -> command units needs GEAR_NUM, read once
        sent = h.client.stats.sent
        for call in (ax.turn(20_001), ax.move_to(4 * (c.VALUE_MAX + 1)), ax.move_to(None),
                     ax.move_by(float("nan")), ax.move_to_command(c.VALUE_MAX + 1),
                     ax.write_param("gear_num", 1),
                     ax.write_param("torque_limit", 100), ax.assign_id(64),
                     ax.position_direct(16_385), ax.wave_frequency(51)):
            with pytest.raises(ArgumentRangeError):
                await call
        assert h.client.stats.sent == sent


async def test_motion_and_readouts_in_realtime() -> None:
    async with harness(1, realtime=True) as h:
        ax = h.axis(1)
        gear = await ax.read_param("gear_num")
        window = U.onrange_to_counts(await ax.read_param("on_range"))
        await ax.move_to(8000, wait=True, timeout=5)  # counts
        assert abs(await ax.position() - 8000) <= window
        await ax.move_to_command(1000, wait=True, timeout=5)  # raw command units
        assert abs(await ax.position() - U.command_to_counts(1000, gear)) <= window
        await ax.turn(300)
        # The servo loop runs in wall-clock time and overshoots a few rpm right after the
        # ~16 ms ramp: wait for the steady range rather than for a fixed time.
        async def steady() -> bool:
            return 250 <= await ax.speed() <= 300

        await wait_until_async(steady, timeout=10, what="steady at 300 rpm")
        raw = await ax.torque_raw()
        assert -700 <= raw <= 700
        peak = U.MODELS[U.DEFAULT_MODEL].peak_current_a
        assert abs(await ax.current()) <= peak  # amperes: 700 = peak, sign flipped to CW+
        await ax.stop()
        await ax.set_origin()
        assert abs(await ax.position()) < 3000


async def test_assign_id_waits_and_readdresses() -> None:
    async with harness(1) as h:
        ax = h.axis(1)
        loop = asyncio.get_running_loop()
        t = loop.time()
        await ax.assign_id(7)
        assert loop.time() - t >= 0.010
        assert ax.drive_id == 7 and await ax.read_id() == 7
        assert h.network.nodes[0].drive_id == 7


async def test_read_timeout_is_bounded_and_retried() -> None:
    async with harness(1, timeout=0.02, retries=2) as h:
        ax = h.axis(9)  # nobody
        loop = asyncio.get_running_loop()
        t = loop.time()
        with pytest.raises(DriveTimeout):
            await ax.status()
        assert 0.06 <= loop.time() - t < 1.0
        assert h.client.stats.retries == 2
        assert not await ax.ping(0.01)
        assert await h.axis(1).ping()


async def test_drive_error_ff_fails_the_read_or_the_next_call() -> None:
    async with harness(1) as h:
        ax = h.axis(1)
        # a foreign/corrupted request that skipped the client's checks
        await h.client.port.send((1 << 5) | DmmFunction.TURN_CONST_SPEED,
                                 (30_000).to_bytes(2, "big"))
        with pytest.raises(DriveError) as info:  # raised by the next call once it has arrived
            await wait_until_async(lambda: _false(ax.status()), timeout=10,
                                   what="the drive error")
        assert info.value.code == 0xFF and info.value.drive_id == 1
        await ax.status()  # raised once


async def test_alarm_push_callback_and_next_call() -> None:
    seen: list[int] = []
    async with harness(1, 2, on_alarm=seen.append) as h:
        got = asyncio.Event()
        h.client.on_alarm(lambda i: got.set())
        h.network.node(2).drive.trip(AlarmCode.OVERHEAT)
        # the server pushes queued alarms from its outbox
        await asyncio.wait_for(got.wait(), 2.0)
        assert seen == [2]
        await h.axis(1).status()  # other drive unaffected
        with pytest.raises(DriveAlarm) as info:
            await h.axis(2).status()
        assert info.value.drive_id == 2
        st = await h.axis(2).status()
        assert st.alarm_code == AlarmCode.OVERHEAT and not st.enabled
        with pytest.raises(DriveAlarm):
            await h.axis(2).wait_idle(1.0)
        await h.axis(2).reset()
        assert (await h.axis(2).status()).alarm_code == AlarmCode.NONE


async def test_sync_move_starts_axes_within_one_control_period() -> None:
    async with harness(1, 2, 3) as h:
        drives = h.network.drives
        await h.client.sync_move({1: 1000, 2: -2000, 3: 500})
        await wait_until_async(lambda: all(n.motion_started_at is not None
                                           for n in h.network.nodes), poll=0.002,
                               timeout=10, what="every axis started")
        starts = [n.motion_started_at for n in h.network.nodes]
        assert None not in starts
        assert max(starts) - min(starts) <= 1 / 4000  # type: ignore[type-var,operator]
        for d in drives:
            d.advance(1.0)
        gear = drives[0].get_param("gear_num")
        assert [d.position for d in drives] == [
            round(U.command_to_counts(v, gear)) for v in (1000, -2000, 500)]


async def test_position_direct_stream_fixed_period() -> None:
    async with harness(1, 2) as h:
        loop = asyncio.get_running_loop()
        t = loop.time()
        stats = await h.client.stream_position_direct({1: [10] * 20, 2: [-5] * 10}, 0.005)
        elapsed = loop.time() - t
        assert stats.cycles == 20 and stats.frames == 30
        assert elapsed >= 19 * 0.005
        await wait_until_async(lambda: h.network.stats.frames >= 30, poll=0.002, timeout=10,
                               what="30 frames at the nodes")
        assert h.network.stats.frames == 30
        with pytest.raises(ArgumentRangeError):
            await h.client.stream_position_direct({1: [10, 20_000]}, 0.001)


async def test_heartbeat_monitor() -> None:
    async with harness(1, timeout=0.02, retries=0) as h:
        lost: list[int] = []
        hb = h.client.start_heartbeat(1, 0.005, lambda i, e: lost.append(i))
        await wait_until_async(lambda: hb.beats >= 5, poll=0.005, timeout=10, what="5 beats")
        assert hb.beats >= 5 and hb.gaps == 0 and not lost
        h.network.nodes[0].drive.assign_id(9)  # drive vanishes from id 1
        await wait_until_async(lambda: lost, poll=0.005, timeout=10, what="the loss reported")
        await hb.stop()
        assert lost and lost[0] == 1


async def test_trace_sees_frames() -> None:
    async with harness(1) as h:
        events: list[tuple[Direction, object]] = []
        await h.axis(1).add_trace(lambda d, item, t: events.append((d, item)))
        await h.axis(1).status()
        assert events[0] == (Direction.TX, cmds.make_read_status(1).frame)
        assert events[1][0] is Direction.RX and isinstance(events[1][1], c.Frame)


async def test_open_can_axis_and_broadcast_id_zero() -> None:
    spec = f"virtual:servobus-dyncan-open-{next(_channels)}"
    network = DynCanNetwork([VirtualDrive(5)])
    node_port = await AsyncCanBus.open(spec)
    stop = asyncio.Event()
    server = asyncio.create_task(serve(network, node_port, stop=stop))
    axis: AsyncAxis = await open_can_axis(spec, drive_id=0, timeout=0.1)
    try:
        assert await axis.read_id() == 5  # a read to id 0 finds the only drive
    finally:
        await axis.close()
        stop.set()
        await server
        await node_port.close()


async def _false(call: Awaitable[object]) -> bool:
    """Await ``call`` and say "not yet" (for a wait that ends by the call raising)."""
    await call
    return False
