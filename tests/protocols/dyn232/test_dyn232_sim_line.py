"""Dyn232Line: the DYN232M front end of the virtual drives, in stepped time (no I/O)."""

from __future__ import annotations

import asyncio
import time

import pytest

from servobus.errors import ArgumentRangeError
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode, DriveConfig, DriveStatus
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.device import Dyn232Line, wrap28
from servobus.protocols.dyn232.inprocess import open_sim_stream, open_sim_url, parse_sim_url
from servobus.protocols.dyn232.pacing import BYTE_TIME_S, WireClock
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.eeprom import EepromStore

H, D, GR = c.HostFunction, c.DriveFunction, c.GeneralReadSelector


def make_line(*ids: int) -> Dyn232Line:
    return Dyn232Line([VirtualDrive(i) for i in ids or (0,)])


def ask(line: Dyn232Line, drive_id: int, fn: c.HostFunction, value: int = 0) -> list[c.Packet]:
    """Send one packet; return the decoded replies (raises on a corrupt reply)."""
    out = line.receive(c.encode(drive_id, fn, value))
    events = c.Framer().feed(out)
    assert all(isinstance(e, c.Packet) for e in events), events
    return [e for e in events if isinstance(e, c.Packet)]


def ask_one(line: Dyn232Line, drive_id: int, fn: c.HostFunction, value: int = 0) -> c.Packet:
    replies = ask(line, drive_id, fn, value)
    assert len(replies) == 1, replies
    return replies[0]


def status(line: Dyn232Line, drive_id: int) -> DriveStatus:
    reply = ask_one(line, drive_id, DF.READ_DRIVE_STATUS)
    assert reply.function == D.IS_STATUS
    return DriveStatus.from_byte(reply.reply_value())


# ---------------------------------------------------------------- manual examples as bytes
def test_example_3_relative_move_bytes_move_drive_3() -> None:
    line = make_line(3)
    assert line.receive(bytes.fromhex("03a380f89e")) == b""  # no reply to a motion command
    line.drives[0].advance(1.0)
    assert line.drives[0].position == round(U.command_to_counts(120))


def test_example_5_and_6_constant_speed_bytes() -> None:
    line = make_line(2)
    drive = line.drives[0]
    assert line.receive(bytes.fromhex("028abcc8")) == b""  # +60 rpm
    drive.advance(0.5)
    assert ask_one(line, 2, DF.GENERAL_READ, GR.SPEED).reply_value() == 60
    assert line.receive(bytes.fromhex("028ac4d0")) == b""  # -60 rpm
    drive.advance(0.5)
    reply = ask_one(line, 2, DF.GENERAL_READ, GR.SPEED)
    assert (reply.drive_id, reply.function, reply.reply_value()) == (2, D.IS_SPEED, -60)


def test_example_1_set_origin_bytes() -> None:
    line = make_line(3)
    line.receive(c.encode(3, DF.GO_RELATIVE_POS, 1000))
    line.drives[0].advance(1.0)
    assert line.drives[0].position != 0
    assert line.receive(bytes.fromhex("03808083")) == b""
    assert ask_one(line, 3, DF.GENERAL_READ, GR.POSITION).reply_value() == 0


# ---------------------------------------------------------------- parameters
@pytest.mark.parametrize("name", P.DYN_PARAMS)
def test_every_parameter_write_and_read_with_its_is_code(name: str) -> None:
    line = make_line(5)
    set_fn, read_fn = c.PARAM_FUNCTIONS[name]
    spec = P.spec(name)
    new = spec.maximum if spec.default != spec.maximum else spec.minimum
    assert line.receive(c.encode(5, set_fn, new)) == b""  # writes never answer
    reply = ask_one(line, 5, read_fn)
    assert reply.function == c.HOST_SPECS[read_fn].reply
    assert (reply.drive_id, reply.reply_value()) == (5, new)
    assert line.drives[0].eeprom.params[name] == new


@pytest.mark.parametrize("name", P.DYN_PARAMS)
def test_out_of_range_parameter_writes_are_ignored(name: str) -> None:
    line = make_line(5)
    set_fn, read_fn = c.PARAM_FUNCTIONS[name]
    spec = P.spec(name)
    before = ask_one(line, 5, read_fn).reply_value()
    for bad in (spec.minimum - 1, spec.maximum + 1):
        assert line.receive(c.encode(5, set_fn, bad)) == b""
    assert ask_one(line, 5, read_fn).reply_value() == before
    assert name not in line.drives[0].eeprom.writes


def test_one_byte_parameter_write_is_unsigned() -> None:
    """Main gain 100 in one byte (0xE4) as DMM's library sends it: read as 100, not -28."""
    line = make_line(1)
    one_byte = c.encode(1, H.SET_MAIN_GAIN, 100, unsigned=True)
    assert len(one_byte) == 4
    line.receive(one_byte)
    assert ask_one(line, 1, H.READ_MAIN_GAIN).reply_value() == 100


def test_parameter_reply_is_one_unsigned_byte() -> None:
    line = make_line(1)
    line.receive(c.encode(1, H.SET_HIGH_SPEED, 127))
    raw = line.receive(c.encode(1, H.READ_HIGH_SPEED))
    assert raw == c.encode(1, D.IS_HIGH_SPEED, 127, unsigned=True)
    assert len(raw) == 4


# ---------------------------------------------------------------- registers, id
def test_config_write_read_and_free_bit() -> None:
    line = make_line(1)
    free = DriveConfig(free=True).to_byte()
    line.receive(c.encode(1, DF.SET_DRIVE_CONFIG, free))
    reply = ask_one(line, 1, DF.READ_DRIVE_CONFIG)
    assert reply.function == D.IS_CONFIG
    assert DriveConfig.from_byte(reply.reply_value()).free
    assert status(line, 1).servo_free
    line.receive(c.encode(1, DF.GO_RELATIVE_POS, 1000))  # ignored while free
    line.drives[0].advance(0.5)
    assert line.drives[0].position == 0
    line.receive(c.encode(1, DF.SET_DRIVE_CONFIG, 0))
    assert not status(line, 1).servo_free


def test_enable_disable_and_reset_selectors_send_nothing() -> None:
    line = make_line(1)
    for sel in (GR.DISABLE, GR.ENABLE, GR.RESET):
        assert line.receive(c.encode(1, DF.GENERAL_READ, sel)) == b""
        if sel is GR.DISABLE:
            assert status(line, 1).servo_free
        else:
            assert not status(line, 1).servo_free


def test_reset_selector_clears_position_and_keeps_eeprom() -> None:
    line = make_line(1)
    line.receive(c.encode(1, H.SET_MAIN_GAIN, 77))
    line.receive(c.encode(1, DF.GO_RELATIVE_POS, 500))
    line.drives[0].advance(0.5)
    assert line.drives[0].position != 0
    line.receive(c.encode(1, DF.GENERAL_READ, GR.RESET))
    assert ask_one(line, 1, DF.GENERAL_READ, GR.POSITION).reply_value() == 0
    assert ask_one(line, 1, H.READ_MAIN_GAIN).reply_value() == 77


def test_status_bits_while_moving_then_on_position() -> None:
    line = make_line(1)
    assert status(line, 1) == DriveStatus(on_position=True, motion_busy=False)
    line.receive(c.encode(1, DF.GO_RELATIVE_POS, 20_000))
    line.drives[0].advance(0.01)
    moving = status(line, 1)
    assert moving.motion_busy and not moving.on_position
    line.drives[0].advance(3.0)
    done = status(line, 1)
    assert done.on_position and not done.motion_busy
    assert line.drives[0].position == round(U.command_to_counts(20_000))


def test_absolute_move_uses_gear_ratio() -> None:
    line = make_line(1)
    line.receive(c.encode(1, H.SET_GEAR_NUMBER, 2048))
    line.receive(c.encode(1, DF.GO_ABSOLUTE_POS, 1000))
    line.drives[0].advance(2.0)
    expected = round(U.command_to_counts(1000, 2048))
    assert ask_one(line, 1, DF.GENERAL_READ, GR.POSITION).reply_value() == expected


def test_read_id_and_assign_id_take_effect_at_once_and_persist() -> None:
    line = make_line(0)
    assert ask_one(line, 0, DF.READ_DRIVE_ID).reply_value() == 0
    assert line.receive(c.encode(0, DF.ASSIGN_DRIVE_ID, 12)) == b""
    assert ask(line, 0, DF.READ_DRIVE_ID) == []  # old id: silence at once
    reply = ask_one(line, 12, DF.READ_DRIVE_ID)
    assert (reply.drive_id, reply.function, reply.reply_value()) == (12, D.IS_DRIVE_ID, 12)
    line.receive(c.encode(12, DF.GENERAL_READ, GR.RESET))  # power cycle
    assert ask_one(line, 12, DF.READ_DRIVE_ID).drive_id == 12


def test_assign_id_outside_0_63_is_ignored() -> None:
    line = make_line(4)
    line.receive(c.encode(4, DF.ASSIGN_DRIVE_ID, 100))
    assert ask_one(line, 4, DF.READ_DRIVE_ID).reply_value() == 4


def test_id_persists_across_simulator_restart(tmp_path: object) -> None:
    path = f"{tmp_path}/eeprom.json"
    line = Dyn232Line([VirtualDrive(1, eeprom=EepromStore(path, key="1"))])
    line.receive(c.encode(1, DF.ASSIGN_DRIVE_ID, 9))
    line.receive(c.encode(9, H.SET_INT_GAIN, 33))
    again = Dyn232Line([VirtualDrive(1, eeprom=EepromStore(path, key="1"))])
    assert ask(again, 1, DF.READ_DRIVE_ID) == []
    assert ask_one(again, 9, H.READ_INT_GAIN).reply_value() == 33


# ---------------------------------------------------------------- addressing
def test_absent_ids_stay_silent() -> None:
    line = make_line(1, 2, 3)
    for drive_id in (0, 4, 63):
        for fn in (DF.READ_DRIVE_STATUS, DF.READ_DRIVE_ID, H.READ_MAIN_GAIN):
            assert line.receive(c.encode(drive_id, fn)) == b""
        assert line.receive(c.encode(drive_id, DF.GENERAL_READ, GR.POSITION)) == b""


def test_each_drive_answers_with_its_own_id() -> None:
    line = make_line(1, 2, 3)
    for drive_id in (1, 2, 3):
        assert ask_one(line, drive_id, DF.READ_DRIVE_ID).drive_id == drive_id


def test_broadcast_commands_reach_every_drive() -> None:
    line = make_line(1, 2, 3)
    # 60, not near the top: from Speed Gain ~100 up an unloaded motor buzzes (5.1,
    # docs/tuning.md) and its speed readout jitters by a few rpm
    assert line.receive(c.encode(c.BROADCAST_ID, H.SET_SPEED_GAIN, 60)) == b""
    line.receive(c.encode(c.BROADCAST_ID, DF.TURN_CONST_SPEED, 100))
    for d in line.drives:
        d.advance(0.5)
    for drive_id in (1, 2, 3):
        assert ask_one(line, drive_id, H.READ_SPEED_GAIN).reply_value() == 60
        assert ask_one(line, drive_id, DF.GENERAL_READ, GR.SPEED).reply_value() == 100


def test_broadcast_read_single_drive_answers_with_own_id() -> None:
    line = make_line(17)
    reply = ask_one(line, c.BROADCAST_ID, DF.READ_DRIVE_ID)
    assert (reply.drive_id, reply.reply_value()) == (17, 17)


def test_broadcast_read_with_several_drives_collides_into_silence() -> None:
    line = make_line(1, 2)
    assert line.receive(c.encode(c.BROADCAST_ID, DF.READ_DRIVE_ID)) == b""
    assert line.collisions == 1


def test_linear_line_words_go_to_the_drives() -> None:
    """Example 7 over broadcast: X, Y, Z = ids 1, 2, 3 start moving (status b5 busy)."""
    line = make_line(1, 2, 3)
    for word in (100, 200, 0, 3):
        assert line.receive(c.encode(c.BROADCAST_ID, DF.MAKE_LINEAR_LINE, word)) == b""
    for d in line.drives:
        d.advance(0.002)
    assert status(line, 1).motion_busy and status(line, 2).motion_busy
    for d in line.drives:
        d.advance(3.0)
    assert [d.position for d in line.drives] == [
        round(U.command_to_counts(v)) for v in (100, 200, 0)]


def test_circular_arc_words_are_accepted_silently() -> None:
    line = make_line(1, 2, 3)
    for word in (-100, 0, 100, 0, 1):
        assert line.receive(c.encode(c.BROADCAST_ID, DF.MAKE_CIRCULAR_ARC, word)) == b""
    assert line.packets == 5


def test_for_motor_define_is_ignored() -> None:
    line = make_line(1)
    before = (line.drives[0].eeprom.writes.copy(), line.drives[0].read_config())
    assert line.receive(c.encode(1, DF.FOR_MOTOR_DEFINE, 5)) == b""
    assert (line.drives[0].eeprom.writes, line.drives[0].read_config()) == before


def test_unknown_general_read_selector_is_silent() -> None:
    line = make_line(1)
    assert line.receive(c.encode(1, DF.GENERAL_READ, 0x1F)) == b""


def test_torque_read_uses_is_trq_current() -> None:
    line = make_line(1)
    reply = ask_one(line, 1, DF.GENERAL_READ, GR.TORQUE)
    assert (reply.function, reply.reply_value()) == (D.IS_TRQ_CURRENT,
                                                     line.drives[0].torque_current)


def test_every_read_function_answers_with_its_is_code() -> None:
    line = make_line(6)
    for spec in c.HOST_SPECS.values():
        if spec.reply is not None:
            assert ask_one(line, 6, spec.function).function == spec.reply, spec.function
    for selector, reply_fn in c.GENERAL_READ_REPLIES.items():
        assert ask_one(line, 6, DF.GENERAL_READ, selector).function == reply_fn


def test_no_reply_functions_never_answer() -> None:
    line = make_line(6)
    for spec in c.HOST_SPECS.values():
        if spec.reply is None and spec.function is not DF.GENERAL_READ:
            value = 0 if spec.function is not DF.ASSIGN_DRIVE_ID else 6
            value = max(spec.minimum, min(spec.maximum, value))
            assert line.receive(c.encode(6, spec.function, value)) == b"", spec.function


# ---------------------------------------------------------------- framing and checksum
def test_bad_checksum_not_executed_and_reported_once() -> None:
    line = make_line(1, 2)
    bad = bytearray(c.encode(1, DF.GO_RELATIVE_POS, 5000))
    bad[-1] ^= 0x01
    assert line.receive(bytes(bad)) == b""
    line.drives[0].advance(0.5)
    assert line.drives[0].position == 0  # not executed
    first = status(line, 1)
    assert first.alarm is AlarmCode.CHECKSUM
    assert status(line, 1).alarm is AlarmCode.NONE  # cleared by the read
    assert status(line, 2).alarm is AlarmCode.NONE  # not addressed
    assert line.checksum_errors == 1


def test_bad_checksum_on_broadcast_marks_every_drive() -> None:
    line = make_line(1, 2)
    bad = bytearray(c.encode(c.BROADCAST_ID, H.SET_MAIN_GAIN, 90))
    bad[-1] ^= 0x10
    line.receive(bytes(bad))
    for drive_id in (1, 2):
        assert status(line, drive_id).alarm is AlarmCode.CHECKSUM
        assert ask_one(line, drive_id, H.READ_MAIN_GAIN).reply_value() != 90


def test_any_chunking_gives_the_same_replies() -> None:
    stream = b"".join(c.encode(i, fn) for i in (1, 2) for fn in
                      (DF.READ_DRIVE_ID, H.READ_GEAR_NUMBER, DF.READ_DRIVE_STATUS))
    whole = make_line(1, 2).receive(stream)
    line = make_line(1, 2)
    split = b"".join(line.receive(stream[i : i + 1]) for i in range(len(stream)))
    assert whole == split and len(c.Framer().feed(whole)) == 6


def test_garbage_between_packets_is_skipped() -> None:
    line = make_line(1)
    out = line.receive(b"\xff\xfe" + c.encode(1, DF.READ_DRIVE_ID)[:2] +
                       c.encode(1, DF.READ_DRIVE_ID) + b"\x99")
    assert c.Framer().feed(out) == [c.Packet(1, D.IS_DRIVE_ID, bytes([1]))]
    assert line.framing_errors >= 1
    assert status(line, 1).alarm is AlarmCode.NONE  # framing errors are not checksum errors


def test_position_readout_wraps_to_28_bits() -> None:
    assert wrap28(c.VALUE_MAX + 1) == c.VALUE_MIN
    assert wrap28(-5) == -5
    assert wrap28(c.VALUE_MIN - 1) == c.VALUE_MAX


# ---------------------------------------------------------------- in-process stream, URL
def test_parse_sim_url() -> None:
    u = parse_sim_url("sim://dyn2?ids=1,2&fast=1")
    assert (u.kind, u.ids, u.paced) == ("dyn2", (1, 2), False)
    assert parse_sim_url("sim://dyn2").ids == (c.FACTORY_ID,)
    assert parse_sim_url("sim://dyn2").paced
    for bad in ("sim://dyn2?ids=64", "sim://dyn2?ids=1,1", "sim://can", "tcp://x:1",
                "sim://dyn2?bogus=1", "sim://dyn2?fast=maybe"):
        with pytest.raises(ArgumentRangeError):
            parse_sim_url(bad)


async def _round_trip(stream: object, request: bytes) -> bytes:
    from servobus.protocols.dyn232.inprocess import SimByteStream

    assert isinstance(stream, SimByteStream)
    await stream.write(request)
    got = b""
    while len(got) < 4 or len(c.Framer().feed(got)) == 0:
        got += await asyncio.wait_for(stream.read(), 2.0)
    return got


def test_inprocess_stream_fast() -> None:
    async def run() -> None:
        stream = open_sim_url("sim://dyn2?ids=1,2&fast=1")
        traced: list[object] = []
        stream.add_trace(lambda d, b, t: traced.append((d, b)))
        assert [d.drive_id for d in stream.drives] == [1, 2]
        got = await _round_trip(stream, c.encode(2, DF.READ_DRIVE_ID))
        assert c.decode(got) == c.Packet(2, D.IS_DRIVE_ID, bytes([2]))
        assert len(traced) == 2
        await stream.close()
        with pytest.raises(ConnectionError):
            await stream.read()

    asyncio.run(run())


def test_inprocess_stream_paced_round_trip_takes_wire_time() -> None:
    async def run() -> None:
        stream = open_sim_stream(ids=(0,), paced=True)
        t = time.monotonic()
        got = await _round_trip(stream, c.encode(0, DF.READ_DRIVE_STATUS))
        elapsed = time.monotonic() - t
        assert len(got) == 4
        assert elapsed >= 8 * BYTE_TIME_S  # 4 + 4 bytes at 38400 8N1 >= 2.08 ms
        await stream.close()

    asyncio.run(run())


def test_wire_clock_queues_bytes() -> None:
    wire = WireClock(0.001)
    assert wire.send(4, 10.0) == (10.0, 10.004)
    assert wire.send(2, 10.001) == (10.004, 10.006)  # waits for the wire to be free
    assert wire.send(1, 20.0) == (20.0, 20.001)
