"""Interop: the servobus EnipAxis against the virtual DYN5 adapter, for every Axis call (and
the DYN5 extras), in Axis units; URLs and options of enip:// and sim://enip."""

from __future__ import annotations

import asyncio
import math

import pytest
from enip_rig import DOWNTIME_S, adapters, rig, url_of
from rig import wait_until_async

from servobus.axis import connect, connect_async
from servobus.axis.base import AsyncAxis
from servobus.errors import ArgumentRangeError, DriveAlarm, DriveTimeout, NotSupported
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.family import DYN5
from servobus.protocols.enip.axis import EnipAxis
from servobus.transport.base import Direction

pytestmark = pytest.mark.timeout(60)


def test_every_abstract_axis_call_is_implemented() -> None:
    assert not EnipAxis.__abstractmethods__
    assert issubclass(EnipAxis, AsyncAxis)


async def test_identity_ids_and_units() -> None:
    async with rig() as (_fleet, axis):
        assert (axis.protocol, axis.family, axis.drive_id) == ("enip", DYN5, 1)
        assert axis.drive_ids == range(1, 254) and axis.counts_per_rev == 65_536
        assert await axis.read_id() == 1
        assert (await axis.identity()).product_name == "DYN5ENIP"
        with pytest.raises(NotSupported) as info:
            await axis.assign_id(5)
        assert info.value.family == "dmm-dyn5"


async def test_readouts_in_axis_units() -> None:
    async with rig() as (fleet, axis):
        drive = fleet.servers[0].drive
        st = await axis.status()
        assert st.enabled and st.in_position and not st.moving and st.family == "dmm-dyn5"
        await axis.turn(600)
        await wait_until_async(lambda: _near(axis.speed(), 600, 15), timeout=5, what="600 rpm")
        # position counts and amperes are the drive's own (Axis: + = increasing position)
        assert abs(await axis.position() - drive.position) < 65_536  # 600 rpm = 10 rev/s
        assert math.isfinite(await axis.current())
        await axis.stop()
        await wait_until_async(lambda: _near(axis.speed(), 0, 5), timeout=5, what="standstill")
        drive.set_disturbance(-0.5)  # a steady load torque: the servo holds with ~1.4 A

        last = [0.0]

        async def holding() -> bool:
            # steady: the servo's PI settles the load step in ~0.1 s (docs/tuning.md), and the
            # two readouts below are read one after the other
            steady = abs(drive.current_a - last[0]) < 0.002
            last[0] = drive.current_a
            return steady and abs(drive.current_a) > 1.0 and await _near(
                axis.current(), drive.current_a, 0.02)

        await wait_until_async(holding, timeout=3, what="steady holding current")
        raw = await axis.torque_raw()
        assert abs(raw) > 100
        # + = CW; within two 0.01 A steps of the readouts (both are whole steps: 1.39 against
        # 1.37 is two steps, which the float difference puts an ulp above 0.02)
        assert await axis.current() == pytest.approx(-raw / 2000 * 20.0, abs=0.02 + 1e-9)


async def _near(value: object, target: float, tol: float) -> bool:
    got = await value  # type: ignore[misc]
    return abs(got - target) <= tol


async def test_moves_convert_counts_through_gear_num() -> None:
    async with rig() as (fleet, axis):
        drive = fleet.servers[0].drive
        await axis.write_param("gear_num", 16384)  # 6.3: command units = counts
        await axis.move_by(5000, wait=True, timeout=10)
        assert abs(drive.position - 5000) <= await axis.position_window()
        await axis.write_param("gear_num", 4096)  # 4 counts per command unit
        await axis.move_to(-8000, wait=True, timeout=10, confirm=True)
        assert abs(await axis.position() + 8000) <= await axis.position_window()
        await axis.move_by_command(1000, wait=True, timeout=10)  # raw: x 4 counts
        assert abs(await axis.position() - (-8000 + 4000)) <= await axis.position_window()
        await axis.move_to_command(0, wait=True, timeout=10)
        assert abs(await axis.position()) <= await axis.position_window()


async def test_arguments_are_checked_before_anything_is_sent() -> None:
    async with rig() as (_fleet, axis):
        sent: list[object] = []
        await axis.add_trace(lambda d, item, t: sent.append(item) if d is Direction.TX else None)
        for bad in (None, 1.5, math.nan, "10", True):
            with pytest.raises(ArgumentRangeError):
                await axis.move_to(bad)  # type: ignore[arg-type]
        with pytest.raises(ArgumentRangeError):
            await axis.move_by(1 << 50)  # no GEAR_NUM reaches it: refused before the gear read
        with pytest.raises(ArgumentRangeError):
            await axis.turn(16385)  # 0x0E: -16384..16384 rpm
        with pytest.raises(ArgumentRangeError):
            await axis.write_param("gear_num", 0)
        with pytest.raises(ArgumentRangeError):
            await axis.write_params({"main_gain": 50, "torque_limit": 0})
        with pytest.raises(ArgumentRangeError):
            await axis.read_param("no_such_parameter")
        with pytest.raises(ArgumentRangeError):
            await axis.write_instance("drive_reset", 0x1234)  # only 0xABCD
        with pytest.raises(ArgumentRangeError):
            await axis.write_instance("motor_position", 0)  # read-only
        with pytest.raises(ArgumentRangeError):
            await axis.torque(math.nan)
        assert sent == []
        assert await axis.read_param("main_gain") == 40


async def test_parameters_are_ram_values_of_the_drive() -> None:
    async with rig() as (fleet, axis):
        names = [p.name for p in axis.parameters()]
        values = await axis.read_params()
        assert list(values) == names and values["gear_num"] == 4096
        await axis.write_params({"max_speed": 60, "memory_test": 33, "torque_speed_limit": 900})
        assert await axis.read_params(["max_speed", "memory_test", "torque_speed_limit"]) == {
            "max_speed": 60, "memory_test": 33, "torque_speed_limit": 900}
        assert fleet.servers[0].drive.get_param("max_speed") == 60
        assert fleet.servers[0].drive.eeprom.params["max_speed"] == 48  # RAM only (4.1)
        assert fleet.servers[0].drive.torque_speed_limit_rpm == 900  # the drive obeys it
        await axis.write_param("gear_num", 100)  # 4.3: 1~16384 (the DYN2 starts at 500)
        assert await axis.read_param("gear_num") == 100


async def test_enable_disable_and_the_status_word() -> None:
    async with rig() as (fleet, axis):
        await axis.disable()
        assert not (await axis.status()).enabled
        assert await axis.read_instance("sw_enable") == dyn5.DISABLE
        await axis.enable()
        assert (await axis.status()).enabled
        fleet.servers[0].drive.trip(AlarmCode.OVER_CURRENT)
        st = await axis.status()
        assert (st.alarm_code, st.alarm_latched, st.enabled) == (2, True, False)
        with pytest.raises(DriveAlarm):
            await axis.wait_idle(timeout=1)


async def test_reset_reconnects_after_the_downtime_and_loses_ram() -> None:
    async with rig() as (fleet, axis):
        server = fleet.servers[0]
        await axis.write_param("max_speed", 70)
        server.drive.trip(AlarmCode.LOST_PHASE)
        loop = asyncio.get_running_loop()
        start = loop.time()
        await axis.reset()
        assert loop.time() - start >= DOWNTIME_S * 0.9
        assert server.stats.resets == 1
        st = await axis.status()
        assert st.alarm_code == 0 and st.enabled  # software enable is on after Reset
        assert await axis.read_param("max_speed") == 48  # RAM lost, EEPROM value back


async def test_reset_that_never_comes_back_is_a_timeout() -> None:
    async with adapters(downtime=5.0) as fleet:
        axis = await connect_async(url_of(fleet), reset_timeout=0.5, timeout=0.2)
        with pytest.raises(DriveTimeout, match="after Reset"):
            await axis.reset()
        await axis.close()


async def test_reset_waits_through_an_adapter_that_hangs_up_while_it_reboots(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """While it reboots after Reset the adapter accepts TCP and hangs up at once. When the
    client's event loop had seen that hang-up (and closed the socket) before the stream was
    built, setting TCP_NODELAY on it raised OSError EBADF, and ``servobus reset`` failed
    with "Bad file descriptor" though the drive did reset. Here every connection made during
    the reboot is handed over only once the loop has closed its socket, so each reconnect
    meets that case; reset() must wait through it until the adapter answers."""
    async with adapters(downtime=1.0) as fleet:
        server = fleet.servers[0]
        axis = await connect_async(url_of(fleet), timeout=0.3)
        loop = asyncio.get_running_loop()
        real = loop.create_connection
        closed_first: list[int] = []

        async def connect_then_see_the_hang_up(*args: object, **kw: object) -> object:
            transport, protocol = await real(*args, **kw)  # type: ignore[arg-type]
            if server.down:
                sock = transport.get_extra_info("socket")
                await wait_until_async(lambda: sock.fileno() == -1, timeout=30,
                                       what="the loop closing the reset connection")
                closed_first.append(1)
            return transport, protocol

        monkeypatch.setattr(loop, "create_connection", connect_then_see_the_hang_up)
        try:
            server.drive.trip(AlarmCode.LOST_PHASE)
            await axis.reset()  # before the fix: OSError [Errno 9] Bad file descriptor
            assert closed_first, "no reconnect met the rebooting adapter"
            assert server.stats.resets == 1
            assert (await axis.status()).alarm_code == 0
        finally:
            await axis.close()


async def test_origin_waves_and_torque_mode() -> None:
    async with rig() as (fleet, axis):
        drive = fleet.servers[0].drive
        await axis.move_by(20_000, wait=True, timeout=10)
        await axis.set_origin()
        assert abs(await axis.position()) <= await axis.position_window()
        await axis.wave_frequency(2)
        await axis.sine_wave(1024)  # 4.4 example 2: 2 Hz, 45 deg
        await wait_until_async(lambda: _moving(axis), timeout=2, what="sine motion")
        await axis.wave_frequency(0)
        with pytest.raises(ArgumentRangeError):
            await axis.square_wave(4097)
        await axis.set_torque_mode(True)
        assert await axis.torque_mode()
        # A load, as in test_enip_adapter's torque test: a bare rotor at 1.5 A reaches the
        # motor's back-EMF speed limit within 0.1 s and its current falls below 1.5 A.
        drive.set_load(inertia=5e-3)
        await axis.torque(1.5)  # 150 units at 20 A peak (4.4 0x26 example)
        assert await axis.read_instance("torque_command") == 150
        # The host's reading and the drive's own current are sampled together, inside one
        # condition: checked one after the other they raced the motor speeding up.
        async def both_at_1_5_a() -> bool:
            return await _near(axis.current(), 1.5, 0.1) and abs(drive.current_a - 1.5) <= 0.1

        await wait_until_async(both_at_1_5_a, timeout=10, what="1.5 A on the host and drive")
        await axis.torque(0)
        await axis.set_torque_mode(False)
        assert not await axis.torque_mode()


async def _moving(axis: EnipAxis) -> bool:
    return abs(await axis.speed()) > 1


async def test_ping_sibling_and_trace() -> None:
    async with rig("127.0.0.1,127.0.0.2") as (_fleet, axis):
        assert await axis.ping()
        other = await axis.sibling(2)
        assert other.ip == "127.0.0.2" and other.drive_id == 2
        assert await other.ping(0.5)
        await other.write_param("memory_test", 9)
        assert await axis.read_param("memory_test") == 0  # another drive
        await other.close()
        assert await axis.ping()  # closing a sibling keeps this session
        ghost = await axis.sibling(9)
        assert not await ghost.ping(0.05)
        with pytest.raises(DriveTimeout):
            await ghost.position()
        seen: list[Direction] = []
        await axis.add_trace(lambda d, item, t: seen.append(d))
        await axis.position()
        assert seen == [Direction.TX, Direction.RX]


def test_sync_facade_and_urls() -> None:
    with connect("sim://enip?ids=1,2", drive_id=2, timeout=0.3) as axis:
        assert axis.drive_id == 2 and axis.status().enabled
        assert axis.sibling(1).ping(timeout=0.5)
    with connect("sim://enip", drive_id=3, timeout=0.3) as axis:  # the drive asked for
        assert axis.read_id() == 3
    for bad, error in (("sim://enip?nonsense=1", ArgumentRangeError),
                       ("enip://127.0.0.1:0", ArgumentRangeError),
                       ("enip://127.0.0.1:1/x", ArgumentRangeError),
                       ("enip://127.0.0.1:1?timeout=-1", ArgumentRangeError),
                       ("enip://127.0.0.1:1?peak_current_a=0", ArgumentRangeError),
                       ("enip://no-such-host.invalid", ArgumentRangeError),
                       ("enip://127.0.0.1:1?connect_timeout=0.5", DriveTimeout)):
        with pytest.raises(error):
            connect(bad)
    with pytest.raises(ArgumentRangeError):
        connect("sim://enip", drive_id=256)


async def test_drive_id_picks_the_daisy_chain_neighbour_and_hostnames_resolve() -> None:
    async with adapters("127.0.0.1,127.0.0.2") as fleet:
        port = fleet.servers[0].tcp_port
        axis = await connect_async(f"enip://127.0.0.1:{port}", drive_id=2)
        assert axis.drive_id == 2
        await axis.write_param("memory_test", 5)
        assert fleet.servers[1].adapter.params.read(0x01) == 5
        await axis.close()
        named = await connect_async(f"enip://localhost:{port}")
        assert named.drive_id == 1
        await named.close()


async def test_units_of_torque_follow_the_peak_current_option() -> None:
    async with adapters() as fleet:
        axis = await connect_async(url_of(fleet) + "?peak_current_a=10")
        assert isinstance(axis, EnipAxis) and axis.options.peak_current_a == 10.0
        await axis.set_torque_mode(True)
        await axis.torque(1.0)  # 1 A of 10 A peak = 200 units
        assert await axis.read_instance(0x26) == 200
        assert U.MODELS[U.DEFAULT_MODEL].peak_current_a == 20.0
        await axis.close()
