"""The virtual RTU line (device side): multi-drop addressing, broadcast, exceptions, bad CRC,
framing by silence and content, and the baud-rate pacing of requests and replies."""

from __future__ import annotations

import asyncio
import time

import pytest
from rig import wait_until_async

from servobus.families.yzaim import registers as Y
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.crc import with_crc
from servobus.protocols.modbus.device import ModbusLine
from servobus.protocols.modbus.inprocess import make_motors
from servobus.protocols.modbus.pacing import RX_BUFFER_BYTES, RtuLineRunner, whole_request
from servobus.protocols.modbus.timing import char_time_s, inter_frame_gap_s
from servobus.transport.base import Direction

pytestmark = pytest.mark.timeout(30)
SPEED = Y.BY_NAME["target_speed"].address
ABS = Y.PAIR_BY_NAME["absolute_position"]
CHAR = char_time_s(19_200)
GAP = inter_frame_gap_s(19_200)
E = C.ExceptionCode


def frame(request: C.Request | C.UnsupportedRequest) -> bytes:
    return C.encode_request(request)


def exception_of(reply: bytes) -> int:
    decoded = C.decode_frame(reply)
    assert isinstance(decoded, C.ExceptionReply), decoded
    return decoded.code


@pytest.fixture
def line() -> ModbusLine:
    return ModbusLine(make_motors((1, 2, 3)))


def test_each_motor_answers_its_own_address_and_absent_ones_are_silent(
        line: ModbusLine) -> None:
    line.motors[1].write_words(SPEED, (222,))
    reply = line.handle(frame(C.ReadHoldingRequest(2, SPEED, 1)))
    assert C.decode_reply(reply, C.ReadHoldingRequest(2, SPEED, 1)) == \
        C.ReadHoldingReply(2, (222,))
    assert line.handle(frame(C.ReadHoldingRequest(9, SPEED, 1))) == b""  # nobody: silence
    assert line.handle(frame(C.WriteSingleRequest(9, SPEED, 5))) == b""
    assert line.unaddressed == 2 and line.replies == 1


def test_broadcast_writes_are_executed_by_all_and_answered_by_none(line: ModbusLine) -> None:
    assert line.handle(frame(C.WriteSingleRequest(0, SPEED, 555))) == b""
    assert [m.registers()["target_speed"] for m in line.motors] == [555, 555, 555]
    assert line.handle(frame(C.WriteMultipleRequest(0, ABS.low, Y.split32(4096)))) == b""
    assert [m.target for m in line.motors] == [4096, 4096, 4096]
    assert line.handle(frame(C.ReadHoldingRequest(0, SPEED, 1))) == b""  # no broadcast reads
    assert line.broadcasts == 3 and line.replies == 0


def test_two_motors_on_one_address_collide_into_silence() -> None:
    line = ModbusLine(make_motors((4,)) + make_motors((4,)))
    assert line.handle(frame(C.WriteSingleRequest(4, SPEED, 42))) == b""
    assert [m.registers()["target_speed"] for m in line.motors] == [42, 42]  # both executed
    assert line.collisions == 1


def test_write_replies_follow_the_standard(line: ModbusLine) -> None:
    request = C.WriteSingleRequest(1, ABS.low, 8192)  # low word alone: moves (motor doc)
    assert line.handle(frame(request)) == frame(request)  # 0x06: an echo
    assert line.motors[0].target == 8192
    request2 = C.WriteMultipleRequest(1, ABS.low, Y.split32(-32768))
    reply = line.handle(frame(request2))
    assert C.decode_reply(reply, request2) == C.WriteMultipleReply(1, ABS.low, 2)
    assert line.motors[0].target == -32768


@pytest.mark.parametrize(("request_", "code"), [
    (C.UnsupportedRequest(1, 0x04, bytes(4)), E.ILLEGAL_FUNCTION),
    (C.ReadHoldingRequest(1, 0x1E, 1), E.ILLEGAL_DATA_ADDRESS),
    (C.ReadHoldingRequest(1, 0x10, 15), E.ILLEGAL_DATA_ADDRESS),  # 0x10..0x1E
    (C.WriteSingleRequest(1, 0x40, 1), E.ILLEGAL_DATA_ADDRESS),
    (C.WriteSingleRequest(1, Y.BY_NAME["motor_speed"].address, 1), E.ILLEGAL_DATA_ADDRESS),
    (C.WriteSingleRequest(1, SPEED, 3001), E.ILLEGAL_DATA_VALUE),
    (C.WriteSingleRequest(1, Y.BY_NAME["special_function"].address, 5), E.ILLEGAL_DATA_VALUE),
    (C.WriteMultipleRequest(1, SPEED, (100, 10000, 400)), E.ILLEGAL_DATA_VALUE),  # 0x04 > 306
])
def test_exceptions(line: ModbusLine, request_: C.Request | C.UnsupportedRequest,
                    code: int) -> None:
    before = line.motors[0].registers()
    assert exception_of(line.handle(frame(request_))) == code
    assert line.motors[0].registers() == before  # nothing of a refused write applied
    assert line.exceptions == 1


def test_count_outside_the_standard_range_is_exception_3() -> None:
    line = ModbusLine(make_motors((1,)))
    raw = with_crc(bytes((1, 0x03, 0, 0, 0, 126)))  # 126 registers: above 125
    assert exception_of(line.handle(raw)) == E.ILLEGAL_DATA_VALUE


def test_writes_while_modbus_enable_is_0_are_exception_4(line: ModbusLine) -> None:
    motor = line.motors[0]
    enable = Y.BY_NAME["modbus_enable"].address
    assert line.handle(frame(C.WriteSingleRequest(1, enable, 0)))  # switching it off works
    assert exception_of(line.handle(frame(C.WriteSingleRequest(1, SPEED, 10)))) == \
        E.SERVER_DEVICE_FAILURE
    assert motor.registers()["target_speed"] == 1000
    assert line.handle(frame(C.ReadHoldingRequest(1, SPEED, 1)))  # reads still work
    assert line.handle(frame(C.WriteMultipleRequest(1, enable, (1, 1))))  # on, then enable
    assert line.handle(frame(C.WriteSingleRequest(1, SPEED, 10)))
    assert motor.registers()["target_speed"] == 10


def test_a_second_cache_write_within_one_cycle_is_busy(line: ModbusLine) -> None:
    motor = line.motors[0]
    cache = Y.PAIR_BY_NAME["position_cache"].low
    sync = Y.BY_NAME["sync_control"].address
    assert line.handle(frame(C.WriteSingleRequest(1, sync, 1)))
    assert line.handle(frame(C.WriteMultipleRequest(1, cache, Y.split32(100))))
    again = frame(C.WriteMultipleRequest(1, cache, Y.split32(200)))
    assert exception_of(line.handle(again)) == E.SERVER_DEVICE_BUSY  # EasyCan's 0x05
    motor.advance(0.003)  # the 2 ms cycle took the first value
    assert line.handle(again)


def test_whole_request_recognises_one_complete_frame() -> None:
    read = frame(C.ReadHoldingRequest(1, 0, 2))
    assert whole_request(read)
    assert not whole_request(read[:-1]) and not whole_request(read + b"\x00")
    assert not whole_request(read[:-1] + bytes((read[-1] ^ 1,)))
    assert whole_request(frame(C.WriteMultipleRequest(1, 0x16, (1, 2))))
    assert not whole_request(frame(C.UnsupportedRequest(1, 0x04, bytes(4))))


# ------------------------------------------------------------------ the runner (in time)


class Host:
    """One host port on a runner, collecting replies with their arrival times."""

    def __init__(self, runner: RtuLineRunner) -> None:
        self.runner = runner
        self.replies: list[tuple[float, bytes]] = []
        self.got = asyncio.Event()
        self.port = runner.open_port(self._deliver)

    def _deliver(self, data: bytes) -> None:
        self.replies.append((time.monotonic(), data))
        self.got.set()

    async def ask(self, data: bytes, timeout: float = 2.0) -> bytes:
        self.got.clear()
        self.runner.submit(self.port, data)
        await asyncio.wait_for(self.got.wait(), timeout)
        return self.replies[-1][1]


@pytest.mark.parametrize("paced", [True, False])
async def test_bad_crc_is_ignored_and_garbage_and_split_frames_resynchronise(
        paced: bool) -> None:
    line = ModbusLine(make_motors((1,)))
    runner = RtuLineRunner(line, paced=paced)
    host = Host(runner)
    read = frame(C.ReadHoldingRequest(1, SPEED, 1))
    answer = C.encode_reply(C.ReadHoldingReply(1, (1000,)))
    try:
        runner.submit(host.port, read[:-1] + bytes((read[-1] ^ 0x40,)))  # bad CRC
        # Silence ends the run (t3.5); the line counts the bad CRC when it drops the frame.
        await wait_until_async(lambda: line.crc_errors >= 1, what="the bad frame dropped")
        assert host.replies == [] and line.frames == 0 and line.crc_errors >= 1
        runner.submit(host.port, b"\xff\x00\x17" + read[:3])  # garbage, then half a frame
        assert await host.ask(read[3:]) == answer  # the other half: one reply
        assert await host.ask(read + b"\x5a") == answer  # trailing junk
        assert await host.ask(read) == answer
        assert line.frames == 3 and line.discarded > 0
    finally:
        await runner.close()


async def test_a_frame_only_silence_can_end_gets_exception_1_after_t35() -> None:
    runner = RtuLineRunner(ModbusLine(make_motors((1,))), paced=True)
    host = Host(runner)
    try:
        t0 = time.monotonic()
        reply = await host.ask(frame(C.UnsupportedRequest(1, 0x2B, b"\x0e\x01\x00")))
        elapsed = time.monotonic() - t0
        assert exception_of(reply) == E.ILLEGAL_FUNCTION
        # 7 request bytes, t3.5 until the silence ends it (the reply may start then), 5 bytes
        assert elapsed >= 12 * CHAR + GAP
    finally:
        await runner.close()


async def test_paced_request_to_reply_is_wire_time_plus_t35() -> None:
    runner = RtuLineRunner(ModbusLine(make_motors((1,))), paced=True)
    host = Host(runner)
    taps: list[tuple[Direction, bytes, float]] = []
    runner.add_tap(lambda d, data, t: taps.append((d, data, t)))
    try:
        times = []
        for _ in range(5):
            t0 = time.monotonic()
            await host.ask(frame(C.ReadHoldingRequest(1, SPEED, 1)))
            times.append(host.replies[-1][0] - t0)
            await asyncio.sleep(0.005)  # a host's pause between requests (the line goes idle)
        expected = (8 + 7) * CHAR + GAP  # 9.64 ms
        # Never sooner than the wire allows; how much later is this machine's pace (a
        # benchmark figure: bench_modbus). The taps below give the wire times exactly.
        assert min(times) >= expected - 0.0002
        (d1, _, t1), (d2, _, t2) = taps[0], taps[1]
        assert (d1, d2) == (Direction.TX, Direction.RX)
        assert t2 - t1 == pytest.approx(GAP + 7 * CHAR, abs=1e-6)  # wire times, exact
    finally:
        await runner.close()


async def test_a_flood_is_cut_at_the_receive_buffer() -> None:
    runner = RtuLineRunner(ModbusLine(make_motors((1,))), paced=True)
    host = Host(runner)
    try:
        runner.submit(host.port, bytes(1000))
        assert host.port.rx_dropped == 1000 - RX_BUFFER_BYTES
    finally:
        await runner.close()


async def test_a_closed_port_gets_no_pending_reply() -> None:
    runner = RtuLineRunner(ModbusLine(make_motors((1,))), paced=True)
    host = Host(runner)
    try:
        runner.submit(host.port, frame(C.ReadHoldingRequest(1, SPEED, 1)))
        assert host.port.pending == 1
        runner.close_port(host.port)
        await asyncio.sleep(0.03)  # "no reply" has no event: 30 ms (> t3.5) for a wrong one
        assert host.replies == [] and len(runner.releases) == 0
    finally:
        await runner.close()
