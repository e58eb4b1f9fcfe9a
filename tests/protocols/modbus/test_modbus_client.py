"""Modbus RTU client on the fault-injecting pair: transactions, silence, corruption, late
replies, exceptions, broadcast, dead links, argument checks, the frame gap, traces."""

from __future__ import annotations

import asyncio
import itertools
import time

import pytest
from modbus_rig import PATHS, rig
from rig import wait_until_async

from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
)
from servobus.families.yzaim import registers as Y
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.protocols.modbus.policy import RtuPolicy
from servobus.protocols.modbus.sniff import RtuFrameEvent
from servobus.protocols.modbus.timing import inter_frame_gap_s, wire_time_s
from servobus.transport.base import Direction
from servobus.transport.pair import Fault, open_pair
from servobus.transport.trace import format_event

pytestmark = pytest.mark.timeout(30)
GAP = inter_frame_gap_s(19_200)
SPEED = Y.BY_NAME["target_speed"].address
ACCEL = Y.BY_NAME["acceleration"].address
ABS = Y.PAIR_BY_NAME["absolute_position"].low


@pytest.mark.parametrize("path", PATHS)
async def test_reads_and_writes_registers(path: str) -> None:
    async with rig(push=PATHS[path]) as r:
        reply = await r.client.write(1, SPEED, [1234])
        assert reply == C.WriteSingleReply(1, SPEED, 1234)  # the standard's echo
        await r.client.write(1, SPEED, [800, 20000])  # 0x02 and 0x03 in one 0x10 frame
        assert await r.client.read(1, SPEED, 2) == (800, 20000)
        assert r.motor(1).registers()["acceleration"] == 20000
        assert r.client.stats.sent == 3 and r.client.stats.replies == 3


@pytest.mark.parametrize("path", PATHS)
async def test_silence_is_drive_timeout_after_bounded_retries(path: str) -> None:
    async with rig(push=PATHS[path], retries=2, timeout=0.05) as r:
        t0 = time.monotonic()
        with pytest.raises(DriveTimeout, match="drive 7") as info:
            await r.client.read(7, SPEED)
        elapsed = time.monotonic() - t0
        assert "3 attempt(s)" in str(info.value)
        assert len(r.sent) == 3 and r.client.stats.timeouts == 3
        assert 3 * 0.05 <= elapsed < 3 * 0.05 + 0.5
        assert await r.client.read(1, SPEED) == (1000,)  # in sync: the next read works


@pytest.mark.parametrize("path", PATHS)
async def test_a_write_is_sent_once_even_when_its_reply_is_lost(path: str) -> None:
    async with rig(push=PATHS[path], timeout=0.05) as r:
        r.faults.drop_next(3, Direction.RX)
        with pytest.raises(DriveTimeout, match="sent once and not re-sent"):
            await r.client.write(1, ABS, Y.split32(16384))
        assert len(r.sent) == 1  # never re-sent: the motor took it once
        assert r.motor(1).target == 16384
        r.faults.clear()
        assert await r.client.read(1, SPEED) == (1000,)


@pytest.mark.parametrize("path", PATHS)
async def test_corrupt_reply_fails_the_attempt_and_the_read_is_retried(path: str) -> None:
    async with rig(push=PATHS[path], timeout=30.0) as r:
        r.faults.corrupt_next(1, Direction.RX)
        t0 = time.monotonic()
        assert await r.client.read(1, ACCEL) == (10000,)
        # Not at the 30 s deadline: retried at once (far inside it, whatever the load).
        assert time.monotonic() - t0 < 15.0
        assert r.client.stats.retries == 1 and r.client.stats.checksum_errors == 1
        r.faults.corrupt_next(3, Direction.RX)
        with pytest.raises(ChecksumError):
            await r.client.read(1, ACCEL)
        assert await r.client.read(1, ACCEL) == (10000,)  # a corrupt value is never returned


def _garbage_before(direction: Direction, data: bytes) -> list[bytes]:
    return [b"\x01\x03\xff\x00" + data] if direction is Direction.RX else [data]


@pytest.mark.parametrize("fault", ["split", "duplicate", "garbage"])
@pytest.mark.parametrize("path", PATHS)
async def test_split_duplicated_and_garbled_replies_keep_sync(path: str, fault: str) -> None:
    async with rig(push=PATHS[path], timeout=0.5) as r:
        await r.client.write(1, SPEED, [111])
        for n in range(5):
            if fault == "split":
                r.faults.split_next(1, Direction.RX, gap_s=0.002)
            elif fault == "duplicate":
                r.faults.duplicate_next(1, Direction.RX)
            else:
                r.faults.custom = _garbage_before
            assert await r.client.read(1, SPEED) == (111,)
            assert await r.client.read(1, ACCEL, 1) == (10000,)
            assert await r.client.read(1, SPEED, 2) == (111, 10000), n
        r.faults.custom = None


@pytest.mark.parametrize("path", PATHS)
async def test_a_late_reply_never_answers_a_later_read(path: str) -> None:
    async with rig(push=PATHS[path], retries=0, timeout=0.05, late_reply_s=0.5) as r:
        r.faults.delay_next(0.15, 1, Direction.RX)
        with pytest.raises(DriveTimeout):
            await r.client.read(1, SPEED)  # 1000, but its reply comes 150 ms later
        r.motor(1).write_words(SPEED, (2000,))  # meanwhile the value changes
        assert await r.client.read(1, SPEED) == (2000,)  # never the stale 1000
        assert r.client.stats.late_replies == 1 and r.client.late_replies.late == 1


async def test_exception_replies_name_the_register_and_the_code() -> None:
    async with rig() as r:
        with pytest.raises(DriveError, match=r"0x001D\.\.0x001E.*exception 2 "
                                             "ILLEGAL_DATA_ADDRESS") as info:
            await r.client.read(1, 0x1D, 2)
        assert info.value.code == 2 and info.value.drive_id == 1
        with pytest.raises(DriveError, match=r"0x0002 \(target_speed\).*exception 3 "
                                             "ILLEGAL_DATA_VALUE") as info:
            await r.client.write(1, SPEED, [5000])  # 0..3000: the motor refuses
        assert info.value.code == 3
        with pytest.raises(DriveError, match=r"motor_speed.*ILLEGAL_DATA_ADDRESS"):
            await r.client.write(1, Y.BY_NAME["motor_speed"].address, [1])  # read-only
        assert len(r.sent) == 3 and r.client.stats.error_replies == 3  # answers: not re-sent
        assert await r.client.read(1, SPEED) == (1000,)  # nothing was applied


async def test_broadcast_write_reaches_every_motor_and_waits_for_nothing() -> None:
    async with rig(ids=(1, 2, 3)) as r:
        assert await r.client.write(C.BROADCAST, SPEED, [777]) is None
        await r.client.read(3, SPEED)  # the line took the broadcast before this
        assert [m.registers()["target_speed"] for m in r.motors] == [777, 777, 777]
        with pytest.raises(ArgumentRangeError, match="broadcast"):
            await r.client.read(C.BROADCAST, SPEED)


@pytest.mark.parametrize("path", PATHS)
async def test_a_dead_link_fails_a_waiting_read_at_once(path: str) -> None:
    async with rig(push=PATHS[path], timeout=60.0) as r:
        r.faults.drop_next(1, Direction.TX)
        reading = asyncio.ensure_future(r.client.read(1, SPEED))
        await wait_until_async(lambda: r.faults.counts[Fault.DROP],
                               what="the request sent (and lost): the read waits")
        t0 = time.monotonic()
        await r.device.close()
        with pytest.raises(ConnectionLost):
            await reading
        # Far below the read's 60 s deadline: the close failed it, not the deadline (a bound
        # that holds on a loaded machine; idle it takes a few ms).
        assert time.monotonic() - t0 < 30.0
        with pytest.raises(ConnectionLost):
            await r.client.read(1, SPEED)


@pytest.mark.parametrize("call", [
    lambda c: c.read(1, SPEED, 0), lambda c: c.read(1, SPEED, 126),
    lambda c: c.read(1, -1), lambda c: c.read(True, SPEED),
    lambda c: c.write(1, SPEED, [70000]), lambda c: c.write(1, SPEED, [-1]),
    lambda c: c.write(256, SPEED, [1]), lambda c: c.read(1, SPEED, retries=-1),
    lambda c: c.read(1, SPEED, timeout=float("nan")), lambda c: c.read(1, SPEED, timeout=0),
])
async def test_bad_arguments_are_refused_before_sending(call: object) -> None:
    async with rig() as r:
        with pytest.raises(ArgumentRangeError):
            await call(r.client)  # type: ignore[operator]
        assert r.sent == []


@pytest.mark.parametrize("options", [
    {"baud": 0}, {"retries": -1}, {"retries": 1.5}, {"turnaround_s": -0.1},
    {"timeout": float("inf")}, {"late_reply_s": -1}, {"frame_gap_s": float("nan")},
    {"eeprom_guard": "yes"}, {"parity": "E"},
])
def test_bad_client_options_are_refused(options: dict[str, object]) -> None:
    with pytest.raises(ArgumentRangeError):
        AsyncModbusClient.check_options(options)


def test_deadline_is_wire_time_gap_and_turnaround() -> None:
    read = C.ReadHoldingRequest(1, 0x0E, 1)
    expected = wire_time_s(8 + 7) + GAP + 0.05  # 7.8 + 1.8 + 50 ms
    assert RtuPolicy().deadline_s(read) == pytest.approx(expected)
    write = C.WriteMultipleRequest(1, ABS, (0, 1))
    assert RtuPolicy(baud=9600).deadline_s(write) == pytest.approx(
        wire_time_s(13 + 8, 9600) + inter_frame_gap_s(9600) + 0.05)
    assert RtuPolicy(timeout=0.3).deadline_s(read) == 0.3
    assert RtuPolicy().deadline_s(read, timeout=0.01) == 0.01
    assert RtuPolicy().gap_s == pytest.approx(GAP)
    assert RtuPolicy(frame_gap_s=0.01).gap_s == 0.01


async def test_the_host_keeps_t35_of_silence_before_each_frame() -> None:
    async with rig() as r:
        for _ in range(10):
            await r.client.read(1, SPEED)
        events = r.wire.events
        gaps = [b.t - a.t for a, b in itertools.pairwise(events)
                if a.direction is Direction.RX and b.direction is Direction.TX]
        assert len(gaps) == 9
        assert min(gaps) >= GAP


async def test_traces_show_decoded_frames_and_timeouts() -> None:
    async with rig(timeout=0.05, retries=0) as r:
        await r.client.read(1, Y.BY_NAME["alarm_code"].address)
        with pytest.raises(DriveTimeout):
            await r.client.read(9, SPEED)
        items = r.trace.items()
        assert isinstance(items[0], RtuFrameEvent) and not items[0].from_drive
        assert items[0].text == "id 1 read 0x000E alarm_code"
        assert isinstance(items[1], RtuFrameEvent) and items[1].from_drive
        assert items[1].text == "id 1 read reply [0]"
        assert isinstance(items[-1], DriveTimeout)
        assert "<- !! DriveTimeout" in format_event(Direction.RX, items[-1])
        assert "-> id 9 read 0x0002 target_speed" in format_event(Direction.TX, items[2])


async def test_a_client_works_on_a_stream_it_did_not_open() -> None:
    """The client takes any ByteStream; a closed client closes it and refuses calls."""
    host, _device = open_pair()
    client = AsyncModbusClient(host, timeout=0.02, retries=0)
    with pytest.raises(DriveTimeout):
        await client.read(1, SPEED)
    await client.close()
    assert client.closed and host.closed
    with pytest.raises(ConnectionLost):
        await client.read(1, SPEED)


def test_fault_kinds_used_here_exist() -> None:
    assert {Fault.DROP, Fault.CORRUPT, Fault.DELAY, Fault.SPLIT, Fault.DUPLICATE} <= set(Fault)
