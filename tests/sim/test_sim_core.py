"""VirtualDrive core in stepped time: profile figures, DTPU, speed modes, waves, servo gains."""

from __future__ import annotations

import itertools
import math

import pytest

from servobus.families.dmm import units as U
from servobus.families.dmm.profile import ptp_profile
from servobus.families.dmm.registers import DriveStatus
from servobus.sim.dmm.drive import CONTROL_HZ, VirtualDrive

DT = 1.0 / CONTROL_HZ


def trace(drive: VirtualDrive, seconds: float, every: int = 1) -> list[tuple[float, int, float,
                                                                            DriveStatus]]:
    """(time, position, speed_rpm, status) sampled every ``every`` control periods."""
    out = []
    for _ in range(round(seconds * CONTROL_HZ / every)):
        drive.advance(DT * every)
        out.append((drive.time, drive.position, drive.speed_rpm, drive.peek_status()))
    return out


def first(rows: list, pred) -> tuple:  # type: ignore[no-untyped-def]
    return next(r for r in rows if pred(r))


def test_appendix_b_in_stepped_time_within_2_percent() -> None:
    d = VirtualDrive(1)
    d.set_param("max_speed", 48)
    d.set_param("max_accel", 30)
    d.set_param("gear_num", 4096)
    prof = ptp_profile(48, 30, 4096, 140_000)
    assert d.move_relative(140_000)
    rows = trace(d, 0.6)
    vmax = max(r[2] for r in rows)
    assert vmax == pytest.approx(1985, rel=0.02)
    t10 = first(rows, lambda r: r[2] >= 0.1 * 1985)[0]
    t90 = first(rows, lambda r: r[2] >= 0.9 * 1985)[0]
    assert 0.8 * 1985 / (t90 - t10) == pytest.approx(19073, rel=0.02)
    t_acc, p_acc = first(rows, lambda r: r[2] >= 0.99 * 1985)[:2]
    assert t_acc == pytest.approx(0.104, rel=0.02)
    assert p_acc / 65536 == pytest.approx(1.72, rel=0.02)
    t_dec = first(rows, lambda r: r[0] > t_acc and r[2] < 0.99 * 1985)[0]
    assert t_dec - t_acc == pytest.approx(0.154, rel=0.02)
    t_end = first(rows, lambda r: not r[3].motion_busy)[0]
    assert t_end == pytest.approx(0.362, rel=0.02)
    assert t_end <= 1.05 * prof.trapezoid_time_s
    assert rows[-1][1] == 560_000
    assert rows[-1][3].on_position


def test_dtpu_new_target_replaces_running_one_speed_continuous() -> None:
    d = VirtualDrive(1)
    amax_rpm_per_step = U.profile_accel_rpm_s(30) * DT
    d.move_relative(140_000)
    rows = trace(d, 0.2)
    assert d.move_absolute(300_000)  # further on: no stop in between
    rows += trace(d, 0.2)
    cruise = [r[2] for r in rows if 0.15 <= r[0] <= 0.4]
    assert min(cruise) > 0.95 * 1985
    assert d.move_absolute(0)  # reverse while cruising
    rows += trace(d, 1.2)
    speeds = [r[2] for r in rows]
    jumps = [abs(b - a) for a, b in itertools.pairwise(speeds)]
    assert max(jumps) < 3 * amax_rpm_per_step  # no speed step anywhere
    assert rows[-1][1] == 0 and not rows[-1][3].motion_busy


def test_relative_moves_accumulate_on_the_running_target() -> None:
    d = VirtualDrive(1)
    d.move_relative(1000)
    d.advance(0.005)
    d.move_relative(1000)
    d.advance(0.5)
    assert d.position == U.command_to_counts(2000)


def test_constant_speed_ramps_at_max_accel_and_stop_holds() -> None:
    d = VirtualDrive(1)
    assert d.turn_const_speed(1000)
    rows = trace(d, 0.2)
    t_reach = first(rows, lambda r: r[2] >= 990)[0]
    assert t_reach == pytest.approx(990 / U.profile_accel_rpm_s(30), rel=0.1)
    assert rows[-1][2] == pytest.approx(1000, abs=1)
    assert not rows[-1][3].motion_busy and not rows[-1][3].on_position
    # stop from a running point-to-point move: brake at Max Accel and hold
    d.move_relative(1_000_000)
    d.advance(0.3)
    t0 = d.time
    assert d.turn_const_speed(0)
    assert not d.peek_status().motion_busy
    rows = trace(d, 0.3)
    t_stop = first(rows, lambda r: abs(r[2]) < 1)[0] - t0
    assert t_stop == pytest.approx(1985 / U.profile_accel_rpm_s(30), rel=0.1)
    held = rows[-1][1]
    d.advance(0.5)
    assert d.position == held and d.peek_status().on_position


def test_speed_mode_soft_start_rise_time() -> None:
    d = VirtualDrive(1)
    d.set_config(0x08 | 0x03)  # speed servo, analog command
    d.set_param("max_accel", 30)
    d.set_analog_input(5.0)  # 3000 rpm
    rows = trace(d, 0.4)
    t10 = first(rows, lambda r: r[2] >= 300)[0]
    t90 = first(rows, lambda r: r[2] >= 2700)[0]
    assert t90 - t10 == pytest.approx(U.soft_start_rise_s(30), rel=0.1)
    assert rows[-1][2] == pytest.approx(3000, rel=0.01)
    assert not d.move_relative(100)  # serial motion ignored outside position/RS232


def test_torque_mode_current_follows_analog() -> None:
    d = VirtualDrive(1, model="DYN2-T1")
    d.set_config(0x10 | 0x03)
    d.set_blocked(True)
    d.set_analog_input(-3.0)
    d.advance(0.5)
    assert d.current_a == pytest.approx(-3.0, rel=0.02)  # 1 A/V on -T1


def test_sine_wave_frequency_and_amplitude_then_stop() -> None:
    d = VirtualDrive(1)
    assert d.set_wave_frequency(5)
    assert d.sine_wave(1024)  # 45 deg swing: +-22.5 deg
    rows = trace(d, 1.0, every=4)
    pos = [r[1] for r in rows[40:]]  # skip the start-up transient
    crossings = sum(1 for a, b in itertools.pairwise(pos) if a < 0 <= b)
    span = (len(pos) - 1) * 4 * DT
    assert crossings / span == pytest.approx(5, abs=0.6)
    assert max(pos) == pytest.approx(1024 * U.WAVE_COUNTS_PER_UNIT / 2, rel=0.05)
    assert d.set_wave_frequency(0)
    d.advance(1.0)
    assert d.position == 0 and d.peek_status().on_position


def test_square_wave_alternates_by_amplitude() -> None:
    d = VirtualDrive(1)
    d.set_wave_frequency(2)
    d.square_wave(4096)  # 180 deg swing: the largest step the lost-phase limit allows
    d.advance(0.2)
    assert d.position == pytest.approx(16384, abs=100)
    d.advance(0.25)
    assert d.position == pytest.approx(-16384, abs=100)
    assert d.alarm == 0
    assert d.square_wave(0)
    d.advance(0.5)
    assert d.position == 0


# The servo gains' effects (5.1, 5.2) are tested on the load models in test_tuning.py.


def test_readouts_come_from_the_model() -> None:
    d = VirtualDrive(1)
    d.set_disturbance(0.72)  # N m against which the servo must hold
    d.advance(1.0)
    assert d.current_a == pytest.approx(-0.72 / U.MODELS["DYN2-TL"].torque_constant_nm_a,
                                        rel=0.02)
    assert d.torque_current == round(d.current_a * 1000)
    assert abs(d.position) <= 1
    d.turn_const_speed(-600)
    d.advance(0.3)
    assert d.speed_rpm == pytest.approx(-600, rel=0.01)


def test_speed_is_realistic_when_free() -> None:
    d = VirtualDrive(1)
    d.turn_const_speed(1000)
    d.advance(0.3)
    d.disable()
    assert d.peek_status().servo_free and not d.move_relative(10)
    d.advance(0.05)
    assert 0 < d.speed_rpm < 1000  # coasting down under friction
    d.enable()
    d.advance(1.0)
    assert d.speed_rpm == pytest.approx(0, abs=0.5) and d.peek_status().on_position


def test_fast_path_does_not_change_results() -> None:
    a, b = VirtualDrive(1), VirtualDrive(1)
    for d in (a, b):
        d.move_relative(3000)
    a.advance(2.0)
    for _ in range(2000):
        b.advance(0.001)
    assert a.position == b.position == 12_000
    assert math.isclose(a.time, b.time)
