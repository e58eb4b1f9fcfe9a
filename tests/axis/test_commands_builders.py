"""The pure ``make_*`` builders of both DMM protocols, byte for byte.

Anchored on the manuals' worked bytes (DYN2 7.6 examples 1-6; DYN CAN section 5/6 frames):
what a builder returns is exactly what goes on the wire, and nothing else.
"""

from __future__ import annotations

import pytest

from servobus.errors import ArgumentRangeError
from servobus.families.dmm.registers import DriveConfig
from servobus.protocols.dyn232 import codec as c232
from servobus.protocols.dyn232 import commands as m232
from servobus.protocols.dyncan import codec as ccan
from servobus.protocols.dyncan import commands as mcan

DYN232 = [
    (m232.make_set_origin(3), "03 80 80 83"),  # 7.6 example 1
    (m232.make_move_absolute(3, 0), "03 81 80 84"),  # example 2
    (m232.make_move_relative(3, 120), "03 a3 80 f8 9e"),  # example 3
    (m232.make_move_relative(3, -120), "03 a3 ff 88 ad"),  # example 4
    (m232.make_turn_const_speed(2, 60), "02 8a bc c8"),  # example 5
    (m232.make_turn_const_speed(2, -60), "02 8a c4 d0"),  # example 6
    (m232.make_turn_const_speed(8, 50), "08 8a b2 c4"),  # 7.2.6 checksum example
    (m232.make_read_status(3), "03 89 80 8c"),  # Read_Drive_Status, one dummy byte 0
    (m232.make_read_param(1, "main_gain"), "01 98 80 99"),  # Read_MainGain
    (m232.make_set_param(1, "main_gain", 40), "01 90 a8 b9"),  # Set_MainGain 40
    (m232.make_read_position(1), "01 8e 9b aa"),  # General_Read 0x1B
    (m232.make_enable(1), "01 8e a0 af"),  # General_Read 0x20
    (m232.make_set_config(1, DriveConfig(absolute=True)), "01 87 84 8c"),
]


@pytest.mark.parametrize(("command", "wire"), DYN232)
def test_dyn232_builders_byte_for_byte(command: m232.Command, wire: str) -> None:
    assert command.to_bytes() == bytes.fromhex(wire)
    packet = c232.decode(command.to_bytes())  # and the bytes say what the builder meant
    assert (packet.drive_id, packet.function) == (command.drive_id, command.function)


DYNCAN = [
    (mcan.make_read_config(3), 0x068, ""),
    (mcan.make_read_status(3), 0x069, ""),
    (mcan.make_turn_const_speed(2, 20_000), 0x04A, "4e 20"),
    (mcan.make_turn_const_speed(2, -60), 0x04A, "c4"),
    (mcan.make_square_wave(2, 4096), 0x04B, "10 00"),
    (mcan.make_wave_frequency(2, 50), 0x04D, "32"),
    (mcan.make_read_position(1), 0x02E, "1b"),
    (mcan.make_read_torque(1), 0x02E, "1e"),
    (mcan.make_sync_load(1, 1000), 0x036, "03 e8"),
    (mcan.make_sync_load(2, -1000, relative=True), 0x057, "fc 18"),
    (mcan.make_sync_trigger(), 0x018, "ff"),
    (mcan.make_position_direct(1, -16_384), 0x03C, "c0 00"),
    (mcan.make_enable(1), 0x039, "00"),
    (mcan.make_disable(1), 0x039, "ff"),
    (mcan.make_read_speed(1), 0x03A, ""),
    (mcan.make_echo(1, bytes.fromhex("de ad be ef")), 0x03E, "de ad be ef"),
    (mcan.make_read_group(1, ccan.Function.READ_PARAM_GROUP3), 0x035, ""),
    (mcan.make_set_param(1, "max_accel", 30), 0x031, "00 1e"),  # 0 = max_speed unchanged
]


@pytest.mark.parametrize(("command", "ident", "data"), DYNCAN)
def test_dyncan_builders_byte_for_byte(command: mcan.CanCommand, ident: int, data: str) -> None:
    assert ccan.encode(command.frame) == (ident, bytes.fromhex(data))


def test_builders_refuse_before_building() -> None:
    for bad in (lambda: m232.make_move_absolute(1, c232.VALUE_MAX + 1),
                lambda: m232.make_turn_const_speed(1, 20_001),
                lambda: m232.make_set_param(1, "gear_num", 499),
                lambda: mcan.make_move_absolute(1, None),  # type: ignore[arg-type]
                lambda: mcan.make_position_direct(1, 16_385),
                lambda: mcan.make_read_status(64)):
        with pytest.raises(ArgumentRangeError):
            bad()
