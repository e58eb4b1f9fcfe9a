"""AsyncDyn232Client / Dyn232Axis over the fault-injecting pair wired to a Dyn232Line.

The drives run in stepped virtual time: every chunk the line receives advances them by
``STEP_S``, so motion completes in a few polls and no test sleeps on the wall clock.
"""

from __future__ import annotations

import asyncio
import itertools
import time
import warnings
from collections.abc import Coroutine
from contextlib import AbstractAsyncContextManager
from typing import Any

import pytest
from dyn232_rig import Rig, rig

from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    DriveAlarm,
    DriveTimeout,
    EepromGuardError,
)
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode, DriveConfig, ServoMode
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.link.eeprom_guard import EepromGuard, EepromWearWarning
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.transport.base import ByteReceiver, Direction, TraceHook
from servobus.transport.pair import Fault, PairStream, PushPairStream

pytestmark = pytest.mark.timeout(20)
#: A servoed motor settles within OnRange of its target (default 10/16384 rev = 40 counts).
TOLERANCE = round(U.onrange_to_counts(P.spec("on_range").default))


def near(actual: int, target: int) -> bool:
    return abs(actual - target) <= TOLERANCE


def bench(ids: tuple[int, ...] = (0,), **client_kw: Any) -> AbstractAsyncContextManager[Rig]:
    """The shared rig (tests/dyn232_rig.py) on the client's push path."""
    return rig(ids, push=True, **client_kw)


# ---------------------------------------------------------------------- basic reads
async def test_reads_parse_every_register_and_parameter() -> None:
    async with bench((5,)) as b:
        ax = b.axis(5)
        drive = b.drives[0]
        assert await ax.read_id() == 5
        assert await ax.drive_status() == drive.peek_status()
        assert (await ax.status()).vendor == drive.peek_status()
        assert await ax.config() == drive.read_config()
        assert await ax.read_params() == {n: drive.get_param(n) for n in P.DYN_PARAMS}
        assert await ax.position() == drive.position
        assert await ax.ping() is True
        assert b.client.stats.timeouts == 0


async def test_move_with_wait_reaches_target_in_counts() -> None:
    async with bench((1,)) as b:
        ax = b.axis(1)
        await ax.write_param("gear_num", 2048)  # command x 4096/2048 x 4 counts
        await ax.move_to(8000, wait=True, timeout=5)  # Axis units: counts (command 1000)
        assert near(await ax.position(), 1000 * 2 * 4)
        await ax.set_origin()
        assert near(await ax.position(), 0)
        await ax.move_by(-2000, wait=True, timeout=5)
        assert near(await ax.position(), -250 * 2 * 4)
        await ax.move_by_command(250, wait=True, timeout=5)  # raw command units: 2000 counts
        assert near(await ax.position(), 0)


async def test_turn_speed_and_stop() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        await ax.turn(600)
        for _ in range(40):  # 0.8 s of virtual time: far more than the ramp takes
            if abs(await ax.speed() - 600) <= 6:
                break
        assert abs(await ax.speed() - 600) <= 6  # within 1 % (servo ripple)
        await ax.stop()
        for _ in range(40):
            if abs(await ax.speed()) <= 6:
                break
        assert abs(await ax.speed()) <= 6
        assert (await ax.status()).moving is False


# ---------------------------------------------------------------------- faults
async def test_corrupted_reply_is_counted_retried_and_never_returned() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        await ax.write_param("main_gain", 77)
        b.faults.corrupt_next(n=1, direction=Direction.RX)
        assert await ax.read_param("main_gain") == 77
        assert b.client.stats.checksum_errors == 1
        assert b.client.stats.retries == 1
        assert any(isinstance(i, ChecksumError) for i in b.trace.items(Direction.RX))


async def test_every_reply_corrupt_raises_checksum_error_not_a_value() -> None:
    async with bench((0,), retries=2) as b:
        b.faults.corrupt_next(n=3, direction=Direction.RX)
        with pytest.raises(ChecksumError):
            await b.axis(0).position()
        assert b.client.stats.checksum_errors == 3
        assert b.wire.tx == 3 * 4  # the read was sent three times


async def test_dropped_reply_is_retried() -> None:
    async with bench((0,)) as b:
        b.faults.drop_next(n=2, direction=Direction.RX)
        assert await b.axis(0).read_id() == 0
        assert b.client.stats.timeouts == 2 and b.client.stats.retries == 2


async def test_silent_drive_times_out_within_its_deadline() -> None:
    async with bench((0,), retries=2, turnaround_s=0.02) as b:
        b.faults.set_rate(Direction.RX, Fault.DROP, 1.0)
        per_try = b.client.reply_deadline_s(4)
        t0 = time.monotonic()
        with pytest.raises(DriveTimeout):
            await b.axis(0).status()
        elapsed = time.monotonic() - t0
        assert elapsed >= per_try * 3 * 0.9  # it did wait for every attempt
        assert elapsed <= per_try * 3 + 0.5  # and gave up in time (generous: loaded CI)
        assert b.wire.tx == 3 * 4


async def test_absent_id_times_out_and_ping_is_false() -> None:
    async with bench((0,), retries=1) as b:
        ghost = b.axis(9)
        with pytest.raises(DriveTimeout):
            await ghost.read_param("main_gain")
        assert await ghost.ping(timeout=0.02) is False
        assert await b.axis(0).ping(timeout=0.5) is True


async def test_motion_is_sent_exactly_once_on_a_faulty_line() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        assert await ax.gear_num() == 4096  # read once, before the count starts
        b.faults.drop_next(n=1, direction=Direction.TX)  # the move vanishes on the wire
        before = b.wire.tx
        await ax.move_to(5000)  # counts: command 1250
        await ax.turn(100)
        await ax.write_param("on_range", 20)
        await ax.set_origin()
        sizes = [len(c.encode(0, f, v)) for f, v in ((DmmFunction.GO_ABSOLUTE_POS, 1250),
                 (DmmFunction.TURN_CONST_SPEED, 100), (c.HostFunction.SET_POS_ON_RANGE, 20),
                 (DmmFunction.SET_ORIGIN, 0))]
        assert b.wire.tx - before == sum(sizes)  # one packet each, never re-sent
        assert b.client.stats.sent == 5  # the gear read and the four packets


async def test_stale_and_foreign_replies_do_not_answer_a_request() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        # A late reply from drive 0 and a reply from another id arrive before our request.
        await b.device.write(c.encode_reply(0, c.DriveFunction.IS_ABS_POS32, 424242))
        await b.device.write(c.encode_reply(3, c.DriveFunction.IS_DRIVE_ID, 3) + b"\x85\x99")
        await asyncio.sleep(0)  # one loop pass (a yield, not a wait): the bytes are delivered
        assert await ax.position() == b.drives[0].position
        # Garbage and a foreign packet in the middle of the reply window: framer resyncs.
        b.faults.custom = lambda d, data: (
            [b"\x91\x92" + c.encode_reply(7, c.DriveFunction.IS_STATUS, 0) + data]
            if d is Direction.RX else [data]
        )
        assert await ax.read_id() == 0
        assert b.client.stats.unmatched >= 1


async def test_split_duplicate_and_delayed_replies_still_parse() -> None:
    async with bench((0,), turnaround_s=0.2) as b:
        ax = b.axis(0)
        b.faults.split_next(direction=Direction.RX, gap_s=0.01)
        assert await ax.read_param("gear_num") == 4096
        b.faults.duplicate_next(direction=Direction.RX)
        assert await ax.read_param("max_speed") == 48
        b.faults.delay_next(0.05, direction=Direction.RX)
        assert await ax.read_param("max_accel") == 30


# ---------------------------------------------------------------------- argument checks
async def test_range_errors_raise_before_any_byte_is_written() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        assert await ax.gear_num() == 4096  # counts -> command units needs GEAR_NUM
        before = b.wire.tx
        bad: list[Coroutine[Any, Any, Any]] = [
            ax.move_to(4 * (c.VALUE_MAX + 1)), ax.move_by(4 * (c.VALUE_MIN - 1)),
            ax.move_to_command(c.VALUE_MAX + 1), ax.move_by_command(c.VALUE_MIN - 1),
            ax.move_to(None), ax.move_by(1.5), ax.move_to(True), ax.turn(20001),
            ax.write_param("main_gain", 0), ax.write_param("gear_num", 499),
            ax.write_param("line_num", 1000),  # not reachable over DYN232M
            ax.read_param("nope"), ax.assign_id(64), ax.sibling(127),
            ax.write_params({"main_gain": 50, "speed_gain": 128}),
        ]
        for coro in bad:
            with pytest.raises(ArgumentRangeError):
                await coro
        assert b.wire.tx == before
        assert b.drives[0].get_param("main_gain") == P.spec("main_gain").default


# ---------------------------------------------------------------------- EEPROM guard
async def test_eeprom_guard_warns_then_refuses_before_sending() -> None:
    now = [0.0]
    guard = EepromGuard(warn_per_window=3, max_per_window=5, window_s=10,
                        clock=lambda: now[0])
    async with bench((0,), eeprom_guard=guard) as b:
        ax = b.axis(0)
        with warnings.catch_warnings():
            warnings.simplefilter("error", EepromWearWarning)
            for v in (10, 11, 12):
                await ax.write_param("main_gain", v)
            with pytest.raises(EepromWearWarning):
                await ax.write_param("main_gain", 13)
            # as an error the warning stops the write: nothing sent, nothing counted
        for v in (14, 15):
            with pytest.warns(EepromWearWarning):
                await ax.write_param("main_gain", v)
        sent = b.wire.tx
        with pytest.raises(EepromGuardError):
            await ax.write_param("main_gain", 16)
        assert b.wire.tx == sent  # refused before anything was sent
        assert await ax.read_param("main_gain") == 15
        await ax.write_param("speed_gain", 30)  # other items are counted separately
        now[0] = 11.0  # the window has passed
        await ax.write_param("main_gain", 17)
        assert await ax.read_param("main_gain") == 17
        assert guard.writes(0, "main_gain") == 6


# ---------------------------------------------------------------------- id, config, params
async def test_assign_id_moves_the_axis_and_persists() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        await ax.assign_id(12)
        assert ax.drive_id == 12
        assert await ax.read_id() == 12
        assert await b.axis(0).ping(timeout=0.02) is False
        b.drives[0].reset()  # power cycle: the id is in EEPROM
        assert await ax.read_id() == 12
        assert b.client.guard.writes(12, "drive_id") == 1


async def test_params_backup_restore_round_trip() -> None:
    async with bench((2,)) as b:
        ax = b.axis(2)
        backup = await ax.read_params()
        changed = {n: (v % 120) + 3 if n != "gear_num" else 1000 for n, v in backup.items()}
        await ax.write_params(changed)
        assert await ax.read_params() == changed
        await ax.write_params(backup)
        assert await ax.read_params() == backup


async def test_config_and_enable_disable() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        await ax.disable()
        assert not (await ax.status()).enabled
        await ax.enable()
        assert (await ax.status()).enabled
        cfg = DriveConfig(servo_mode=ServoMode.SPEED)
        await ax.set_config(cfg)
        assert await ax.config() == cfg


async def test_wait_idle_raises_drive_alarm_and_reset_clears_it() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        b.drives[0].trip(AlarmCode.OVER_CURRENT)
        with pytest.raises(DriveAlarm) as info:
            await ax.wait_idle(timeout=1, poll=0)
        assert info.value.code == int(AlarmCode.OVER_CURRENT)
        await ax.reset()
        assert (await ax.wait_idle(timeout=1, poll=0)).alarm_code == AlarmCode.NONE


async def test_checksum_notice_from_drive_is_not_an_alarm() -> None:
    async with bench((0,)) as b:
        ax = b.axis(0)
        await ax.gear_num()  # the move's packet is the next one on the wire
        b.faults.corrupt_next(direction=Direction.TX)  # the drive gets a bad packet
        await ax.move_to(400)  # not executed by the drive (checksum)
        st = await ax.wait_idle(timeout=1, poll=0)  # code 4 reported once, not raised
        assert st.alarm_code in (AlarmCode.CHECKSUM, AlarmCode.NONE)
        assert near(await ax.position(), 0)


async def test_query_pacing_spaces_queries() -> None:
    """Measured where the bytes leave (the cable's TX trace, stamped in its write): the
    client's pacing clock is stamped after that write returned, so no CPU load can bring
    two queries closer than the interval (it used to be stamped when the send was decided,
    and this test failed 2 runs in 8 under load with a 1 ms allowance)."""
    interval = 0.02
    async with bench((0,), query_interval_s=interval) as b:
        ax = b.axis(0)
        sends: list[float] = []
        b.host.add_trace(lambda d, data, t: sends.append(t) if d is Direction.TX else None)
        for _ in range(6):
            await ax.position()  # one query each (status() adds a speed read at rest)
        gaps = [later - earlier for earlier, later in itertools.pairwise(sends)]
        assert len(gaps) == 5 and min(gaps) >= interval, gaps


class SlowWrites:
    """A push stream whose writes take time before the bytes leave (a draining serial port,
    a loaded host): delegates to ``inner`` after sleeping ``delays`` in turn."""

    def __init__(self, inner: PairStream, delays: list[float]) -> None:
        self.inner = inner
        self.delays = delays
        self.left: list[float] = []

    async def write(self, data: bytes) -> None:
        if self.delays:
            await asyncio.sleep(self.delays.pop(0))  # scripted: a write that takes this long
        self.left.append(time.monotonic())
        await self.inner.write(data)

    async def read(self, max_bytes: int = 4096) -> bytes:
        return await self.inner.read(max_bytes)

    def discard_input(self) -> None:
        self.inner.discard_input()

    async def close(self) -> None:
        await self.inner.close()

    def add_trace(self, hook: TraceHook) -> None:
        self.inner.add_trace(hook)

    def set_receiver(self, receiver: ByteReceiver | None) -> None:
        assert isinstance(self.inner, PushPairStream)
        self.inner.set_receiver(receiver)


async def test_query_pacing_holds_when_writes_take_time() -> None:
    """Regression (issue #9): a write that takes 15 ms before its bytes leave let the next
    query leave 5 ms after it while the pacing clock was stamped at the send decision."""
    interval = 0.02
    async with bench((0,)) as b:
        slow = SlowWrites(b.host, [0.015, 0.0, 0.012, 0.0, 0.018, 0.0])
        client = AsyncDyn232Client(slow, query_interval_s=interval)
        ax = Dyn232Axis(client, 0, owns_client=False)
        for _ in range(6):
            await ax.position()  # one query each (status() adds a speed read at rest)
        gaps = [later - earlier for earlier, later in itertools.pairwise(slow.left)]
        assert min(gaps) >= interval, gaps


async def test_trace_hook_sees_decoded_packets_both_ways() -> None:
    async with bench((0,)) as b:
        await b.axis(0).read_param("main_gain")
        tx = b.trace.items(Direction.TX)
        rx = b.trace.items(Direction.RX)
        assert tx == [c.Packet(0, c.HostFunction.READ_MAIN_GAIN, b"\x00")]
        assert isinstance(rx[0], c.Packet) and rx[0].function == c.DriveFunction.IS_MAIN_GAIN


async def test_lock_serialises_concurrent_transactions() -> None:
    async with bench((0, 1, 2)) as b:
        results = await asyncio.gather(*(b.axis(i % 3).read_id() for i in range(30)))
        assert results == [i % 3 for i in range(30)]
        assert b.client.stats.timeouts == 0


async def test_broadcast_linear_line_moves_three_axes() -> None:
    async with bench((1, 2, 3)) as b:
        await b.client.linear_line(100, 200, 0, 3)
        for i, want in ((1, 100), (2, 200), (3, 0)):
            await b.axis(i).wait_idle(timeout=5, poll=0)
            assert near(await b.axis(i).position(), want * 4)
