"""VirtualDrive core: interpolation, alarms, EEPROM, origin/absolute mode, JP3 I/O."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from servobus.families.dmm import units as U
from servobus.families.dmm.profile import (
    accel_counts_per_s2,
    pack_arc_word,
    speed_counts_per_s,
    trapezoid_time,
)
from servobus.families.dmm.registers import AlarmCode
from servobus.sim.dmm.drive import CONTROL_HZ, VirtualDrive
from servobus.sim.dmm.eeprom import EEPROM_CYCLE_LIMIT, EepromStore

DT = 1.0 / CONTROL_HZ


def axes() -> list[VirtualDrive]:
    return [VirtualDrive(i) for i in (1, 2, 3)]


def run_together(drives: list[VirtualDrive], seconds: float) -> list[tuple[list[int], list[bool]]]:
    rows = []
    for _ in range(round(seconds * CONTROL_HZ / 4)):
        for d in drives:
            d.advance(4 * DT)
        rows.append(([d.position for d in drives],
                     [d.peek_status().motion_busy for d in drives]))
    return rows


def broadcast(drives: list[VirtualDrive], method: str, words: list[int]) -> None:
    for w in words:
        for d in drives:
            getattr(d, method)(w)


def test_linear_line_straight_all_axes_finish_together() -> None:
    xyz = axes()
    broadcast(xyz, "linear_line_word", [1000, 2000, -500, 64])
    rows = run_together(xyz, 1.0)
    end = [U.command_to_counts(v) for v in (1000, 2000, -500)]
    assert rows[-1][0] == end
    length = math.dist((0, 0, 0), end)
    for pos, _ in rows:  # distance from the line through 0 and end
        t = sum(p * e for p, e in zip(pos, end, strict=True)) / length**2
        off = math.dist(pos, [t * e for e in end])
        assert off <= 0.005 * length
    done = [next(i for i, (_, busy) in enumerate(rows) if not busy[k]) for k in range(3)]
    assert len(set(done)) == 1 and done[0] > 0
    # path speed = F/127 x profile speed: feedrate 64 takes about twice as long as 127
    assert rows[0][1] == [True, True, True]


def test_line_feedrate_scales_path_speed() -> None:
    """Path speed = |F|/127 x profile speed (3-4-5 line, so the path is longer than X)."""
    dist = U.command_to_counts(50_000)

    def duration(feed: int) -> float:
        xyz = axes()
        broadcast(xyz, "linear_line_word", [30_000, 40_000, 0, feed])
        rows = run_together(xyz, 3.0)
        return next(i for i, (_, busy) in enumerate(rows) if not busy[0]) * 4 * DT

    for feed in (127, 32):
        ta, tc, _ = trapezoid_time(dist, feed / 127 * speed_counts_per_s(48, 4096),
                                   accel_counts_per_s2(30, 4096))
        assert duration(feed) == pytest.approx(2 * ta + tc, rel=0.03)


def test_arc_radius_and_two_half_arcs_make_a_circle() -> None:
    xyz = axes()
    # example 8: from (0,0) CW about (100,0) to (200,0), scaled x10
    broadcast(xyz, "circular_arc_word", [-1000, 0, 1000, 0, pack_arc_word(0, 20)])
    rows = run_together(xyz, 2.0)
    cx, r = U.command_to_counts(1000), U.command_to_counts(1000)
    for pos, _ in rows:
        assert math.hypot(pos[0] - cx, pos[1]) == pytest.approx(r, rel=0.01)
        assert pos[2] == 0
    assert max(p[1] for p, _ in rows) > 0.99 * r  # CW from the left: over the top
    assert rows[-1][0][:2] == [round(2 * r), 0]
    assert not any(rows[-1][1]) and rows[0][1] == [True, True, False]
    broadcast(xyz, "circular_arc_word", [1000, 0, -1000, 0, pack_arc_word(0, 20)])
    rows = run_together(xyz, 2.0)
    assert min(p[1] for p, _ in rows) < -0.99 * r
    assert rows[-1][0] == [0, 0, 0]


def test_ccw_arc_in_yz_plane() -> None:
    xyz = axes()
    broadcast(xyz, "circular_arc_word", [-1000, 0, 0, 1000, pack_arc_word(1, -50)])
    rows = run_together(xyz, 2.0)
    assert rows[-1][0] == [0, U.command_to_counts(1000), U.command_to_counts(1000)]
    assert min(p[2] for p, _ in rows) < -0.9 * U.command_to_counts(1000)  # CCW: below


# ---------------------------------------------------------------- alarms
def tripped(d: VirtualDrive, seen: list[AlarmCode], code: AlarmCode) -> None:
    assert d.alarm is code and seen == [code]
    st = d.peek_status()
    assert st.alarm is code and st.servo_free and d.alarm_output
    assert not d.move_relative(10) and not d.turn_const_speed(10)
    d.enable()
    d.advance(0.5)
    assert d.alarm is code  # latched
    d.reset()
    assert d.alarm is AlarmCode.NONE and not d.peek_status().servo_free


def watch(d: VirtualDrive) -> list[AlarmCode]:
    seen: list[AlarmCode] = []
    d.alarm_listeners.append(lambda _d, code: seen.append(code))
    return seen


def deg_to_command(deg: float) -> int:
    return round(deg / 360 * U.COUNTS_PER_REV / 4)


def test_lost_phase_beyond_180_deg_trips_at_once() -> None:
    d = VirtualDrive(1)
    seen = watch(d)
    d.set_blocked(True)
    d.move_relative(deg_to_command(200))
    d.advance(0.3)
    tripped(d, seen, AlarmCode.LOST_PHASE)


def test_lost_phase_90_deg_for_2_s() -> None:
    d = VirtualDrive(1)
    seen = watch(d)
    d.set_blocked(True)
    d.move_relative(deg_to_command(120))
    d.advance(1.9)
    assert d.alarm is AlarmCode.NONE
    d.advance(0.3)
    tripped(d, seen, AlarmCode.LOST_PHASE)


def test_over_current_when_stalled_at_peak_current() -> None:
    d = VirtualDrive(1)
    seen = watch(d)
    d.set_blocked(True)
    d.move_relative(deg_to_command(30))
    d.advance(0.5)
    assert d.alarm is AlarmCode.NONE
    assert abs(d.current_a) == pytest.approx(20.0)  # DYN2-TL peak
    d.advance(0.8)
    tripped(d, seen, AlarmCode.OVER_CURRENT)


def test_overheat_from_i2t() -> None:
    d = VirtualDrive(1, model="DYN2-T1")
    m = U.MODELS["DYN2-T1"]
    seen = watch(d)
    d.set_disturbance(2 * m.rated_current_a * m.torque_constant_nm_a)  # hold at 2x rated
    d.advance(10.0)
    assert d.alarm is AlarmCode.NONE and 0.5 < d.heat_fraction < 1.0
    d.advance(10.0)
    d.set_disturbance(0.0)
    tripped(d, seen, AlarmCode.OVERHEAT)


def test_rated_current_never_overheats() -> None:
    d = VirtualDrive(1)
    m = U.MODELS["DYN2-TL"]
    d.set_disturbance(m.rated_current_a * m.torque_constant_nm_a)
    d.advance(120.0)
    assert d.alarm is AlarmCode.NONE


def test_over_voltage() -> None:
    d = VirtualDrive(1)
    seen = watch(d)
    d.set_bus_voltage(80.0)
    d.advance(0.1)
    assert d.alarm is AlarmCode.NONE
    d.set_bus_voltage(81.0)
    tripped(d, seen, AlarmCode.OVER_VOLTAGE)  # reset() with 81 V still on trips again
    assert d.alarm is AlarmCode.NONE
    d.advance(0.01)
    assert d.alarm is AlarmCode.OVER_VOLTAGE


def test_explicit_trip_and_checksum_notice_does_not_latch() -> None:
    d = VirtualDrive(1)
    d.note_checksum_error()
    assert d.read_status().alarm is AlarmCode.CHECKSUM
    assert d.read_status().alarm is AlarmCode.NONE
    seen = watch(d)
    d.trip(AlarmCode.OVER_CURRENT)
    tripped(d, seen, AlarmCode.OVER_CURRENT)


# ---------------------------------------------------------------- EEPROM
def test_eeprom_survives_reset_and_restart(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    d = VirtualDrive(0, eeprom=EepromStore(path))
    assert d.set_param("main_gain", 77)
    assert d.set_param("max_speed", 100, ram_only=True)
    assert not d.set_param("main_gain", 128)
    assert d.assign_id(5)
    d.reset()
    assert d.get_param("main_gain") == 77 and d.get_param("max_speed") == 48
    assert d.drive_id == 5
    d2 = VirtualDrive(0, eeprom=EepromStore(path))  # simulator restart
    assert d2.get_param("main_gain") == 77 and d2.drive_id == 5
    assert d2.eeprom.writes["main_gain"] == 1


def test_eeprom_wear_out_past_one_million_writes() -> None:
    store = EepromStore()
    store.writes["main_gain"] = EEPROM_CYCLE_LIMIT - 1
    d = VirtualDrive(1, eeprom=store)
    assert d.set_param("main_gain", 50)  # the millionth write still sticks
    assert d.set_param("main_gain", 60)  # worn: works in RAM ...
    assert d.get_param("main_gain") == 60 and store.worn("main_gain")
    d.reset()
    assert d.get_param("main_gain") == 50  # ... but is lost at power-off


def test_can_group2_first_ten_writes_go_to_eeprom() -> None:
    d = VirtualDrive(1)
    assert not d.set_speed_accel_group(128, 0)
    for i in range(12):
        assert d.set_speed_accel_group(10 + i, 0)
    assert d.get_param("max_speed") == 21 and d.get_param("max_accel") == 30
    assert d.eeprom.writes["max_speed"] == 10
    d.reset()
    assert d.get_param("max_speed") == 19
    assert d.set_speed_accel_group(0, 7)
    assert d.eeprom.params["max_accel"] == 7  # counter restarts at power-on


# ---------------------------------------------------------------- origin, modes
def test_set_origin_relative_and_absolute_power_on() -> None:
    d = VirtualDrive(1)
    d.move_relative(5000)
    d.advance(0.5)
    d.set_origin()
    assert d.position == 0
    d.move_absolute(2000)
    d.advance(0.5)
    assert d.position == 8000
    d.reset()  # relative mode: reads 0
    assert d.position == 0
    d.set_config(0x04)  # absolute mode
    d.reset()
    assert d.position == 8000 and d.peek_status().motion_busy
    d.advance(0.5)
    assert d.position == 0  # back to the stored zero


def test_move_direct_has_no_smoothing() -> None:
    d = VirtualDrive(1)
    assert d.move_direct(400)
    d.advance(0.3)
    assert d.position == 1600


def test_pulse_input_4x_gear_pulses_per_rev() -> None:
    d = VirtualDrive(1)
    assert not d.input_pulses(100)  # RS232 mode: ignored
    d.set_config(0x02)  # Pulse/Dir
    d.set_param("gear_num", 500)
    assert not d.move_relative(10)
    assert d.input_pulses(2000, seconds=0.2)  # 4 x 500 pulses = 1 rev
    d.advance(0.5)
    assert d.position == 65536
    levels = [(False, False), (True, False)] * 10  # 10 STEP edges, DIR low = reverse
    assert d.input_pulse_levels(levels) == -10
    d.pulse_format = "ab"
    ab = [(False, False), (True, False), (True, True), (False, True)] * 5
    assert d.input_pulse_levels(ab) == 5
    d.advance(0.3)
    assert d.position == round(65536 - 5 * 16384 / 500)


def test_analog_position_input_and_enable_input() -> None:
    d = VirtualDrive(1)
    d.set_config(0x03)  # analog command, position servo
    d.set_analog_input(10.0)  # 90 deg at gear 4096
    d.advance(0.5)
    assert d.position == 16384
    assert d.peek_status().jp3_pin2
    d.set_enable_input(False)
    assert d.peek_status().servo_free
    d.set_enable_input(True)
    assert not d.peek_status().servo_free


def test_outputs_onpos_zri_bko() -> None:
    d = VirtualDrive(1)
    assert d.onpos_output is True and d.brake_released is None and not d.alarm_output
    assert d.zri_output
    d.turn_const_speed(600)
    d.advance(1.0)
    assert d.onpos_output is False and d.zri_count >= 8
    d.set_param("on_range", 127)
    assert d.brake_released is None  # takes effect after a power cycle
    d.reset()
    assert d.onpos_output is None and d.brake_released is True
    d.disable()
    assert d.brake_released is False
