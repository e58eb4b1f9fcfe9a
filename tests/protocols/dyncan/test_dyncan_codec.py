"""DYN CAN codec: golden frames for every function code, the torque example, properties."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError, FramingError
from servobus.families.dmm import units as U
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyncan import codec as c

F = c.Function

# (frame built by the codec, identifier, data hex) - hand-computed: id = drive << 5 | FC,
# data big-endian two's complement (docs/dyncan.md).
GOLDEN: list[tuple[c.Frame, int, str]] = [
    (c.request(1, DF.SET_ORIGIN, 0xFF), 0x020, "ff"),
    (c.request(1, DF.SET_ORIGIN), 0x020, ""),
    (c.request(1, DF.GO_ABSOLUTE_POS, 4096), 0x021, "10 00"),
    (c.request(1, DF.GO_ABSOLUTE_POS, -1), 0x021, "ff"),
    (c.request(1, DF.GO_ABSOLUTE_POS, 134_217_727), 0x021, "07 ff ff ff"),
    (c.request(1, DF.GO_ABSOLUTE_POS, -134_217_728), 0x021, "f8 00 00 00"),
    (c.request(0, DF.MAKE_LINEAR_LINE, 200), 0x002, "00 c8"),
    (c.request(2, DF.GO_RELATIVE_POS, -120), 0x043, "88"),
    (c.request(2, DF.GO_RELATIVE_POS, 128), 0x043, "00 80"),
    (c.request(0, DF.MAKE_CIRCULAR_ARC, -1000), 0x004, "fc 18"),
    (c.request(1, DF.ASSIGN_DRIVE_ID, 5), 0x025, "05"),
    (c.request(5, DF.READ_DRIVE_ID), 0x0A6, ""),
    (c.reply(5, DF.READ_DRIVE_ID, 5), 0x0A6, "05"),
    (c.request(3, DF.SET_DRIVE_CONFIG, 0x24), 0x067, "24"),
    (c.request(3, DF.READ_DRIVE_CONFIG), 0x068, ""),
    (c.reply(3, DF.READ_DRIVE_CONFIG, 0x24), 0x068, "24"),
    (c.request(3, DF.READ_DRIVE_STATUS), 0x069, ""),
    (c.reply(3, DF.READ_DRIVE_STATUS, 0x21), 0x069, "21"),
    (c.request(2, DF.TURN_CONST_SPEED, 20_000), 0x04A, "4e 20"),
    (c.request(2, DF.TURN_CONST_SPEED, -60), 0x04A, "c4"),
    (c.request(2, DF.SQUARE_WAVE, 4096), 0x04B, "10 00"),
    (c.request(2, DF.SIN_WAVE, 1024), 0x04C, "04 00"),
    (c.request(2, DF.SS_FREQUENCY, 50), 0x04D, "32"),
    (c.request(1, DF.GENERAL_READ, 0x1B), 0x02E, "1b"),
    (c.reply(1, DF.GENERAL_READ, 65_536), 0x02E, "01 00 00"),
    (c.request(1, DF.GENERAL_READ, 0x1E), 0x02E, "1e"),
    (c.reply(1, DF.GENERAL_READ, -157), 0x02E, "ff 63"),  # torque example (docs/dyncan.md)
    (c.Frame(1, DF.FOR_MOTOR_DEFINE), 0x02F, ""),
    (c.request(1, F.SET_PARAM_GROUP1, fields=(40, 0, 20, 127)), 0x030, "28 00 14 7f"),
    (c.request(1, F.SET_PARAM_GROUP2, fields=(48, 30)), 0x031, "30 1e"),
    (c.request(1, F.SET_PARAM_GROUP3, fields=(10, 16_384, 4095)), 0x032, "0a 40 00 0f ff"),
    (c.request(1, F.READ_PARAM_GROUP1), 0x033, ""),
    (c.reply(1, F.READ_PARAM_GROUP1, fields=(40, 40, 20, 127)), 0x033, "28 28 14 7f"),
    (c.reply(1, F.READ_PARAM_GROUP2, fields=(48, 30)), 0x034, "30 1e"),
    (c.reply(1, F.READ_PARAM_GROUP3, fields=(10, 4096, 4000)), 0x035, "0a 10 00 0f a0"),
    (c.request(1, F.GO_ABSOLUTE_POS_SYNC, 1000), 0x036, "03 e8"),
    (c.request(2, F.GO_RELATIVE_POS_SYNC, -1000), 0x057, "fc 18"),
    (c.request(0, F.SYNC_TRIGGER, c.SyncTrigger.ABSOLUTE), 0x018, "ff"),
    (c.request(0, F.SYNC_TRIGGER, c.SyncTrigger.RELATIVE), 0x018, "ee"),
    (c.request(1, F.SERVO_DISABLE, c.ServoCommand.ENABLE), 0x039, "00"),
    (c.request(1, F.SERVO_DISABLE, c.ServoCommand.DISABLE), 0x039, "ff"),
    (c.request(1, F.READ_MOTOR_SPEED), 0x03A, ""),
    (c.reply(1, F.READ_MOTOR_SPEED, -3000), 0x03A, "f4 48"),
    (c.reply(1, F.READ_MOTOR_SPEED, 5), 0x03A, "00 05"),  # always 2 bytes
    (c.Frame(1, F.TBD), 0x03B, ""),
    (c.request(1, F.POSITION_DIRECT, 16_384), 0x03C, "40 00"),
    (c.request(1, F.POSITION_DIRECT, -16_384), 0x03C, "c0 00"),
    (c.drive_error(1, c.DriveErrorCode.INVALID_DATA), 0x03D, "ff"),
    (c.drive_error(1, c.DriveErrorCode.ALARM), 0x03D, "ee"),
    (c.request(1, F.ECHO, raw=bytes.fromhex("de ad be ef")), 0x03E, "de ad be ef"),
    (c.request(1, F.DIAGNOSTIC_COUNTER), 0x03F, ""),
    (c.reply(1, F.DIAGNOSTIC_COUNTER, 255), 0x03F, "ff"),
    (c.request(63, F.DIAGNOSTIC_COUNTER), 0x7FF, ""),
]


def test_table_covers_every_function_code() -> None:
    assert sorted(c.SPECS) == list(range(32))
    assert {f.function for f, _, _ in GOLDEN} == set(range(32))


@pytest.mark.parametrize(("frame", "ident", "hexdata"), GOLDEN)
def test_golden_encode(frame: c.Frame, ident: int, hexdata: str) -> None:
    assert c.encode(frame) == (ident, bytes.fromhex(hexdata))


@pytest.mark.parametrize(("frame", "ident", "hexdata"), GOLDEN)
def test_golden_decode(frame: c.Frame, ident: int, hexdata: str) -> None:
    assert c.decode(ident, bytes.fromhex(hexdata)) == frame


def test_torque_example_amps() -> None:
    # docs/dyncan.md: 0xFF63 = -157; -157 / 700 x 20 A = -4.48 A; x 0.774 Nm/A = -3.47 Nm
    value = c.decode(0x02E, bytes.fromhex("ff63")).value
    assert value == -157
    ratio = round(value / U.CAN_TORQUE_FULL_SCALE, 3)  # the manual rounds to 0.224 first
    assert ratio == -0.224
    amps = ratio * 20.0
    assert round(amps, 2) == -4.48
    assert round(amps * 0.774, 2) == -3.47


def test_table_lengths_match_section5() -> None:
    s = c.SPECS
    assert s[F.SET_PARAM_GROUP3].sent == (5, 5)
    assert s[F.READ_PARAM_GROUP3].returned == (5, 5)
    assert s[F.READ_PARAM_GROUP1].returned == (4, 4)
    assert s[DF.TURN_CONST_SPEED].sent == (1, 2)
    assert s[DF.SQUARE_WAVE].sent == (1, 3)
    assert s[DF.GENERAL_READ].returned == (1, 4)
    assert s[F.ECHO].sent == s[F.ECHO].returned == (4, 4)
    assert s[DF.SET_ORIGIN].sent == (0, 1)
    assert not s[F.SYNC_TRIGGER].expects_reply


def test_param_groups_map_every_can_parameter() -> None:
    assert c.PARAM_GROUPS["line_num"] == (F.SET_PARAM_GROUP3, F.READ_PARAM_GROUP3, 2)
    assert c.PARAM_GROUPS["max_accel"] == (F.SET_PARAM_GROUP2, F.READ_PARAM_GROUP2, 1)
    assert "torque_limit" not in c.PARAM_GROUPS


def test_field_valid_zero_means_unchanged() -> None:
    gear = c.SPECS[F.SET_PARAM_GROUP3].fields[1]
    assert c.field_valid(gear, 0) and c.field_valid(gear, 500) and c.field_valid(gear, 16_384)
    assert not c.field_valid(gear, 499) and not c.field_valid(gear, 16_385)


def test_errors() -> None:
    with pytest.raises(FramingError):
        c.decode(0x800, b"")
    with pytest.raises(ArgumentRangeError):
        c.arbitration_id(64, 1)
    with pytest.raises(ArgumentRangeError):
        c.request(1, DF.TURN_CONST_SPEED, 40_000)  # does not fit 2 bytes
    with pytest.raises(ArgumentRangeError):
        c.request(1, F.SET_PARAM_GROUP3, fields=(10, 70_000, 0))


def test_describe_guesses_direction() -> None:
    assert c.describe(c.request(1, DF.READ_DRIVE_STATUS)) == "host -> id 1: READ_DRIVE_STATUS"
    assert c.describe(c.reply(1, DF.READ_DRIVE_STATUS, 0x21)).startswith("drive id 1 -> host")
    assert "POSITION" in c.describe(c.request(1, DF.GENERAL_READ, 0x1B))
    assert "RELATIVE" in c.describe(c.request(0, F.SYNC_TRIGGER, 0xEE))
    assert "line_num=unchanged" in c.describe(c.request(1, F.SET_PARAM_GROUP3,
                                                        fields=(10, 0, 0)))
    assert c.describe(c.drive_error(2, c.DriveErrorCode.INVALID_DATA)).endswith("INVALID_DATA")


@given(st.integers(c.VALUE_MIN, c.VALUE_MAX), st.integers(1, 63))
def test_position_roundtrip(value: int, drive_id: int) -> None:
    ident, data = c.encode(c.request(drive_id, DF.GO_RELATIVE_POS, value))
    assert 1 <= len(data) <= 4
    assert c.decode(ident, data).value == value
    # fewest bytes
    if len(data) > 1:
        assert c.decode_signed(data[1:]) != value
