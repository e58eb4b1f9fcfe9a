"""Virtual DYN CAN nodes at frame level (no bus): section 6 behaviour on the shared core."""

from __future__ import annotations

import pytest

from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode, DriveStatus
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.sim.dmm.drive import CONTROL_HZ, VirtualDrive

F = c.Function
ERR = c.DriveErrorCode


def net(*ids: int) -> DynCanNetwork:
    return DynCanNetwork([VirtualDrive(i) for i in ids])


def raw(drive_id: int, fn: F, data: bytes) -> c.Frame:
    return c.Frame(drive_id, fn, data)


def sig(value: int, n: int) -> bytes:
    return value.to_bytes(n, "big", signed=True)


# Every range the manual lists, with the first value outside it on each side.
DRIVE_ERROR_CASES = [
    (DF.GO_ABSOLUTE_POS, sig(c.VALUE_MAX + 1, 4)),
    (DF.GO_ABSOLUTE_POS, sig(c.VALUE_MIN - 1, 4)),
    (DF.GO_RELATIVE_POS, sig(c.VALUE_MAX + 1, 4)),
    (DF.MAKE_LINEAR_LINE, sig(c.VALUE_MIN - 1, 4)),
    (DF.MAKE_CIRCULAR_ARC, sig(c.VALUE_MAX + 1, 4)),
    (F.GO_ABSOLUTE_POS_SYNC, sig(c.VALUE_MAX + 1, 4)),
    (F.GO_RELATIVE_POS_SYNC, sig(c.VALUE_MIN - 1, 4)),
    (DF.TURN_CONST_SPEED, sig(20_001, 2)),
    (DF.TURN_CONST_SPEED, sig(-20_001, 2)),
    (DF.SQUARE_WAVE, sig(4_097, 2)),
    (DF.SQUARE_WAVE, sig(-1, 1)),
    (DF.SIN_WAVE, sig(4_097, 3)),
    (DF.SIN_WAVE, sig(-1, 2)),
    (DF.SS_FREQUENCY, sig(51, 1)),
    (DF.SS_FREQUENCY, sig(-1, 1)),
    (F.SET_PARAM_GROUP1, bytes([128, 0, 0, 0])),
    (F.SET_PARAM_GROUP1, bytes([0, 0, 0, 255])),
    (F.SET_PARAM_GROUP2, bytes([0, 128])),
    (F.SET_PARAM_GROUP3, bytes([128, 0, 0, 0, 0])),
    (F.SET_PARAM_GROUP3, bytes([0]) + (499).to_bytes(2, "big") + bytes(2)),
    (F.SET_PARAM_GROUP3, bytes([0]) + (16_385).to_bytes(2, "big") + bytes(2)),
    (F.SET_PARAM_GROUP3, bytes(3) + (499).to_bytes(2, "big")),
    (F.SET_PARAM_GROUP3, bytes(3) + (4_096).to_bytes(2, "big")),
    (DF.ASSIGN_DRIVE_ID, bytes([65])),
    (DF.ASSIGN_DRIVE_ID, bytes([255])),
]


@pytest.mark.parametrize(("fn", "data"), DRIVE_ERROR_CASES)
def test_drive_error_ff_for_every_listed_range(fn: F, data: bytes) -> None:
    n = net(1)
    before = (n.drives[0].eeprom.params.copy(), n.drives[0].drive_id)
    assert n.handle(raw(1, fn, data)) == [c.drive_error(1, ERR.INVALID_DATA)]
    assert (n.drives[0].eeprom.params, n.drives[0].drive_id) == before  # nothing applied
    assert not n.drives[0].peek_status().motion_busy


BOUNDARY_OK = [
    (DF.GO_ABSOLUTE_POS, sig(c.VALUE_MAX, 4)),
    (DF.TURN_CONST_SPEED, sig(-20_000, 2)),
    (DF.SQUARE_WAVE, sig(4_096, 2)),
    (DF.SIN_WAVE, sig(0, 1)),
    (DF.SS_FREQUENCY, sig(50, 1)),
    (F.SET_PARAM_GROUP1, bytes([127, 1, 0, 0])),
    (F.SET_PARAM_GROUP3, bytes([1]) + (16_384).to_bytes(2, "big") + (4_095).to_bytes(2, "big")),
    (F.SET_PARAM_GROUP3, bytes([0]) + (500).to_bytes(2, "big") + (500).to_bytes(2, "big")),
    (DF.ASSIGN_DRIVE_ID, bytes([64])),  # inside 0..64: no error (not applied: see module)
    (DF.ASSIGN_DRIVE_ID, bytes([0])),
    (F.POSITION_DIRECT, sig(16_385, 2)),  # PD: no Drive Error listed -> ignored
]


@pytest.mark.parametrize(("fn", "data"), BOUNDARY_OK)
def test_no_drive_error_inside_ranges(fn: F, data: bytes) -> None:
    n = net(1)
    assert n.handle(raw(1, fn, data)) == []
    assert n.drives[0].drive_id == 1


def test_param_groups_write_read_and_zero_unchanged() -> None:
    n = net(2)
    d = n.drives[0]
    n.handle(c.request(2, F.SET_PARAM_GROUP1, fields=(50, 0, 30, 0)))
    n.handle(c.request(2, F.SET_PARAM_GROUP3, fields=(0, 2048, 1000)))
    assert d.get_param("main_gain") == 50 and d.get_param("int_gain") == 30
    assert d.get_param("speed_gain") == P.spec("speed_gain").default
    (g1,) = n.handle(c.request(2, F.READ_PARAM_GROUP1))
    assert g1.arbitration_id == (2 << 5) | 0x13
    assert g1.fields() == (50, P.spec("speed_gain").default, 30, P.spec("trq_cons").default)
    (g3,) = n.handle(c.request(2, F.READ_PARAM_GROUP3))
    assert g3.fields() == (P.spec("on_range").default, 2048, 1000)
    n.handle(c.request(2, F.SET_PARAM_GROUP2, fields=(60, 0)))
    (g2,) = n.handle(c.request(2, F.READ_PARAM_GROUP2))
    assert g2.fields() == (60, P.spec("max_accel").default)


def test_sync_trigger_broadcast_starts_axes_in_the_same_control_period() -> None:
    n = net(1, 2, 3)
    n.handle(c.request(1, F.GO_ABSOLUTE_POS_SYNC, 1000))
    n.handle(c.request(2, F.GO_RELATIVE_POS_SYNC, -500))
    n.handle(c.request(3, F.GO_ABSOLUTE_POS_SYNC, 300))
    for d in n.drives:
        d.advance(0.05)
    assert all(not d.peek_status().motion_busy and d.position == 0 for d in n.drives)
    assert n.handle(c.request(0, F.SYNC_TRIGGER, c.SyncTrigger.ABSOLUTE)) == []
    starts = [n.node(i).motion_started_at for i in (1, 3)]
    assert None not in starts
    assert n.node(2).motion_started_at is None  # relative load waits for 0xEE
    n.handle(c.request(0, F.SYNC_TRIGGER, c.SyncTrigger.RELATIVE))
    times = [n.node(i).motion_started_at for i in (1, 2, 3)]
    assert max(times) - min(times) <= 1 / CONTROL_HZ  # type: ignore[operator,type-var]
    for d in n.drives:
        d.advance(0.5)
    gear = P.spec("gear_num").default
    assert n.drives[0].position == round(U.command_to_counts(1000, gear))
    assert n.drives[1].position == round(U.command_to_counts(-500, gear))
    # consumed: a second trigger does not move again
    n.handle(c.request(0, F.SYNC_TRIGGER, c.SyncTrigger.RELATIVE))
    n.drives[1].advance(0.5)
    assert n.drives[1].position == round(U.command_to_counts(-500, gear))


def test_broadcast_read_answers_on_own_identifiers() -> None:
    n = net(4, 5)
    replies = n.handle(c.request(0, DF.READ_DRIVE_ID))
    assert sorted((r.arbitration_id, r.data) for r in replies) == [
        ((4 << 5) | 6, b"\x04"), ((5 << 5) | 6, b"\x05")]


def test_assign_and_read_id() -> None:
    n = net(1)
    assert n.handle(c.request(1, DF.ASSIGN_DRIVE_ID, 9)) == []
    assert n.handle(c.request(1, DF.READ_DRIVE_ID)) == []
    assert n.handle(c.request(9, DF.READ_DRIVE_ID)) == [c.reply(9, DF.READ_DRIVE_ID, 9)]


def test_diagnostic_counter_increments_and_wraps() -> None:
    n = net(1)
    got = [n.handle(c.request(1, F.DIAGNOSTIC_COUNTER))[0].data[0] for _ in range(258)]
    assert got[:3] == [0, 1, 2]
    assert got[255:] == [255, 0, 1]


def test_echo() -> None:
    n = net(1)
    frame = c.request(1, F.ECHO, raw=b"\x01\x02\xfe\xff")
    assert n.handle(frame) == [frame]


def test_set_origin_zero_or_one_byte() -> None:
    n = net(1)
    d = n.drives[0]
    n.handle(c.request(1, DF.GO_RELATIVE_POS, 100))
    d.advance(0.5)
    assert d.position != 0
    n.handle(raw(1, DF.SET_ORIGIN, b""))
    assert d.position == 0
    n.handle(c.request(1, DF.GO_RELATIVE_POS, 100))
    d.advance(0.5)
    n.handle(raw(1, DF.SET_ORIGIN, b"\x12"))  # not 0xFF: ignored
    assert d.position != 0
    n.handle(raw(1, DF.SET_ORIGIN, b"\xff"))
    assert d.position == 0


def test_servo_disable_and_status() -> None:
    n = net(1)
    n.handle(c.request(1, F.SERVO_DISABLE, c.ServoCommand.DISABLE))
    (st,) = n.handle(c.request(1, DF.READ_DRIVE_STATUS))
    assert DriveStatus.from_byte(st.data[0]).servo_free
    n.handle(c.request(1, F.SERVO_DISABLE, c.ServoCommand.ENABLE))
    (st,) = n.handle(c.request(1, DF.READ_DRIVE_STATUS))
    assert not DriveStatus.from_byte(st.data[0]).servo_free


def test_speed_position_and_general_read() -> None:
    n = net(1)
    d = n.drives[0]
    n.handle(c.request(1, DF.TURN_CONST_SPEED, 600))
    d.advance(0.5)
    (sp,) = n.handle(c.request(1, F.READ_MOTOR_SPEED))
    assert len(sp.data) == 2 and sp.value == round(d.speed_rpm) and sp.value > 500
    (pos,) = n.handle(c.request(1, DF.GENERAL_READ, 0x1B))
    assert pos.function == DF.GENERAL_READ and pos.value == d.position > 0
    (tq,) = n.handle(c.request(1, DF.GENERAL_READ, 0x1E))
    assert -700 <= tq.value <= 700
    assert n.handle(c.request(1, DF.GENERAL_READ, 0x55)) == []  # unknown selector


def test_position_direct_moves() -> None:
    n = net(1)
    d = n.drives[0]
    n.handle(c.request(1, F.POSITION_DIRECT, 100))
    d.advance(0.2)
    assert d.position != 0


def test_malformed_lengths_are_ignored() -> None:
    n = net(1)
    assert n.handle(raw(1, F.SET_PARAM_GROUP3, b"\x01\x02")) == []
    assert n.handle(raw(1, DF.READ_DRIVE_STATUS, b"\x00")) == []
    assert n.stats.malformed == 2


def test_alarm_push_ee() -> None:
    n = net(3)
    n.drives[0].trip(AlarmCode.OVER_CURRENT)
    assert n.take_outbox() == [c.drive_error(3, ERR.ALARM)]
    assert n.take_outbox() == []


def test_torque_scale_700_peak_and_ccw_positive() -> None:
    n = net(1)
    d = n.drives[0]
    n.handle(c.request(1, DF.TURN_CONST_SPEED, 3000))
    d.advance(0.01)  # accelerating CW: current positive (CW) in the core
    assert d.current_a > 0
    (tq,) = n.handle(c.request(1, DF.GENERAL_READ, 0x1E))
    assert tq.value < 0  # section 6: negative reading = torque applied CW
    assert tq.value == round(-d.current_a / d.model.peak_current_a * U.CAN_TORQUE_FULL_SCALE)


def test_group2_saves_to_eeprom_only_first_ten_times() -> None:
    n = net(1)
    d = n.drives[0]
    for v in range(60, 71):  # 11 writes
        n.handle(c.request(1, F.SET_PARAM_GROUP2, fields=(v, 0)))
    assert d.get_param("max_speed") == 70
    assert d.eeprom.params["max_speed"] == 69  # the 11th stayed in RAM
    d.reset()
    (g2,) = n.handle(c.request(1, F.READ_PARAM_GROUP2))
    assert g2.fields()[0] == 69


# ---------------------------------------------------------------------- issue 13 deviations
@pytest.mark.parametrize(("function", "dummies"), [
    (DF.READ_DRIVE_CONFIG, 1), (F.READ_PARAM_GROUP1, 1), (F.READ_PARAM_GROUP2, 1),
    (F.READ_PARAM_GROUP3, 2), (F.READ_MOTOR_SPEED, 2), (F.DIAGNOSTIC_COUNTER, 1),
])
def test_dyncan_5_reads_with_the_total_data_dummy_bytes_are_answered(function: F,
                                                                     dummies: int) -> None:
    """Section 5: the "Total Data" column counts dummy bytes a host may send with a read."""
    network = DynCanNetwork([VirtualDrive(1)])
    plain = network.handle(c.Frame(1, function, b""))
    padded = network.handle(c.Frame(1, function, b"\x00" * dummies))
    assert len(plain) == len(padded) == 1 and padded[0].function == function
    assert network.handle(c.Frame(1, function, b"\x00" * (dummies + 1))) == []  # too long


def test_dyncan_4_sim_refuses_bit_rates_the_manual_does_not_list() -> None:
    from click.testing import CliRunner

    from servobus.cli.main import cli

    result = CliRunner().invoke(cli, ["sim", "dyncan", "--bitrate", "300000", "--duration", "0"])
    assert result.exit_code == 2 and "300000" in result.output
