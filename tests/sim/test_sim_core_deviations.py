"""Deviations from the DYN2 manual an audit found in the virtual drive (issue 13), each named
after its manual section: DTPU blending (7.5), the motor's voltage limit (1.1, 2.5, 4.1),
absolute mode homing (7.3; DYN CAN 6) and commands ignored during an alarm (6.1)."""

from __future__ import annotations

import pytest

from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c232
from servobus.protocols.dyn232.device import Dyn232Line
from servobus.protocols.dyncan import codec as ccan
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.sim.dmm.drive import CONTROL_HZ, VirtualDrive

DT = 1.0 / CONTROL_HZ
H = c232.HostFunction
F = ccan.Function
DEG_PER_COUNT = 360.0 / U.COUNTS_PER_REV
CRUISE_RPM = U.profile_speed_rpm(48)  # 1985 rpm: MaxSpd 48, GEAR_NUM 4096 (7.4.1)


# ---------------------------------------------------------------- 7.5 DTPU blending
class Run:
    """Three axis drives X, Y, Z stepped together; X's current, error and speeds recorded."""

    def __init__(self) -> None:
        self.xyz = [VirtualDrive(i) for i in (1, 2, 3)]
        self.x = self.xyz[0]
        self.peak_current = 0.0
        self.peak_error_deg = 0.0
        self.ref_speeds: list[float] = []  # X reference speed, rpm, every period

    def line(self, dx: int, dy: int, dz: int, feed: int = 127) -> None:
        for word in (dx, dy, dz, feed):
            for d in self.xyz:
                assert d.linear_line_word(word)

    def step(self, seconds: float, *, record: bool = False) -> None:
        eng = self.x._engine
        for _ in range(round(seconds * CONTROL_HZ)):
            before = eng.ref
            for d in self.xyz:
                d.advance(DT)
            if record:
                self.peak_current = max(self.peak_current, abs(self.x.current_a))
                self.peak_error_deg = max(self.peak_error_deg,
                                          abs(eng.ref - eng.p) * DEG_PER_COUNT)
                self.ref_speeds.append(U.counts_per_s_to_rpm((eng.ref - before) / DT))

    @property
    def reference(self) -> float:
        return self.x._engine.ref - self.x._origin


def test_7_5_dtpu_blends_a_new_line_into_the_running_motion() -> None:
    """The issue's scenario: X at feed 127 (1985 rpm), a new line at 0.15 s. Before: the
    reference restarted from 0 rpm, 19.7 A of 20 A peak and 23.7 deg following error;
    point-to-point DTPU under the same conditions: 0.6 A, 3.0 deg."""
    run = Run()
    run.line(100_000, 0, 0)
    run.step(0.15)
    start = run.reference
    run.line(100_000, 0, 0)
    run.step(1.5, record=True)
    assert run.peak_current < 2.0
    assert run.peak_error_deg < 4.0
    assert min(run.ref_speeds[:400]) > 0.95 * CRUISE_RPM  # the cruise goes on
    assert run.x.position == round(start + U.command_to_counts(100_000))
    assert not run.x.peek_status().motion_busy


def test_7_5_dtpu_a_line_across_the_running_line_turns_smoothly() -> None:
    """A perpendicular line: X's speed is handed over (brakes out, no step) while Y starts."""
    run = Run()
    run.line(100_000, 0, 0)
    run.step(0.15)
    start = run.reference
    run.line(0, 100_000, 0)
    run.step(2.0, record=True)
    steps = [abs(b - a) for a, b in zip(run.ref_speeds, run.ref_speeds[1:], strict=False)]
    accel_rpm_s = U.profile_accel_rpm_s(30)
    assert max(steps) / DT < 2.5 * accel_rpm_s  # never more than ~2 x Max Accel
    assert run.peak_current < 4.0 and run.peak_error_deg < 5.0
    assert run.x.position == round(start)  # X ends where the line started: dX = 0
    assert run.xyz[1].position == U.command_to_counts(100_000)


def test_7_5_dtpu_point_to_point_during_a_line_continues_from_its_speed() -> None:
    run = Run()
    run.line(100_000, 0, 0)
    run.step(0.15)
    assert run.x.move_relative(100_000)
    run.step(1.5, record=True)
    assert run.peak_current < 2.0 and run.peak_error_deg < 4.0
    assert min(run.ref_speeds[:400]) > 0.95 * CRUISE_RPM


def test_7_5_dtpu_a_line_during_a_point_to_point_move_is_handed_over() -> None:
    run = Run()
    assert run.x.move_relative(100_000)
    run.step(0.15)
    start = run.reference
    run.line(100_000, 0, 0)
    run.step(1.5, record=True)
    assert run.peak_current < 4.0 and run.peak_error_deg < 5.0
    assert min(run.ref_speeds[:400]) > 0.0  # never restarts from standstill
    assert run.x.position == round(start + U.command_to_counts(100_000))


@pytest.mark.parametrize("feed", [127, 64])
@pytest.mark.parametrize("length", [100_000, 1_000_000])
def test_7_5_dtpu_a_line_during_a_point_to_point_move_holds_max_speed(feed: int,
                                                                     length: int) -> None:
    """Issue 18.5: a point-to-point move cruising at Max Speed 48 (1,985 rpm) interrupted by a
    line: the line speeds up while the handed-over speed decays, and the sum reached 2,549 rpm
    (+28 %). The configured Max Speed holds through the handover; the end point stays exact."""
    run = Run()
    assert run.x.move_relative(100_000)
    run.step(0.15)
    start = run.reference
    run.line(length, 0, 0, feed)
    cruise_cps = U.rpm_to_counts_per_s(CRUISE_RPM) * feed / 127
    run.step(1.0 + U.command_to_counts(length) / cruise_cps, record=True)
    assert max(abs(v) for v in run.ref_speeds) <= CRUISE_RPM * 1.001
    assert min(run.ref_speeds[:400]) > 0.0  # never restarts from standstill
    assert run.x.position == round(start + U.command_to_counts(length))
    assert not run.x.peek_status().motion_busy


# ---------------------------------------------------------------- 1.1 voltage limit
def test_1_1_max_speed_127_saturates_at_the_voltage_limit_and_lost_phase_trips() -> None:
    """MaxSpd 127 asks for (130^2/16) x 12.21 = 12,897 rpm (7.4.1); the motor runs out of
    voltage near the manual's 5,000 rpm speed range, the error grows and lost phase trips."""
    d = VirtualDrive(1)
    assert d.set_param("max_speed", 127)
    assert d.move_relative(10_000_000)
    top = 0.0
    while d.alarm is AlarmCode.NONE and d.time < 3.0:
        d.advance(DT * 4)
        top = max(top, abs(d.speed_rpm))
    assert d.alarm is AlarmCode.LOST_PHASE
    assert 5_000 <= top <= 5_600


def test_1_1_speed_mode_saturates_and_a_higher_bus_voltage_raises_the_limit() -> None:
    """4.2: +10 V asks 6,000 rpm. At the rated 60 V bus the motor tops out near 5,500 rpm;
    at 75 V (the permissible maximum, 1.1) it reaches 6,000 (2.5: voltage/speed gradient)."""
    d = VirtualDrive(1)
    d.set_config(0x08)  # speed servo
    d.set_analog_input(10.0)
    d.advance(1.5)
    assert 5_000 <= d.speed_rpm <= 5_600
    d.set_bus_voltage(75.0)
    d.advance(1.0)
    assert d.speed_rpm == pytest.approx(6_000, rel=0.01)
    d.set_bus_voltage(60.0)
    d.set_analog_input(5.0)
    d.advance(1.0)
    assert d.speed_rpm == pytest.approx(3_000, rel=0.01)  # inside the range: as commanded


# ---------------------------------------------------------------- 7.3 absolute mode
def test_7_3_absolute_mode_homes_to_zero_then_accepts_commands() -> None:
    """DYN CAN 6 (Set_Origin): the motor moves to the absolute zero, "then starts accepting
    command"; commands during that move are ignored."""
    d = VirtualDrive(1)
    d.move_relative(5000)  # 20,000 counts from the zero
    d.advance(0.5)
    assert d.set_config(0x04)  # absolute mode
    d.reset()
    assert d.peek_status().motion_busy
    assert not d.move_relative(1000)
    assert not d.set_param("main_gain", 60)
    assert d.get_param("main_gain") != 60
    d.advance(0.5)
    assert d.position == 0 and not d.peek_status().motion_busy
    assert d.move_relative(1000)
    d.advance(0.5)
    assert d.position == 4000


# ---------------------------------------------------------------- 6.1 alarm
def test_6_1_an_alarm_ignores_every_command_and_answers_reads() -> None:
    """6.1: "All commands including pulse, analog and RS232 will be ignored"; parameter,
    config, id and origin writes included, and nothing reaches the EEPROM."""
    d = VirtualDrive(1)
    d.trip(AlarmCode.OVER_CURRENT)
    writes = dict(d.eeprom.writes)
    assert not d.set_param("main_gain", 60)
    assert not d.set_speed_accel_group(60, 0)
    assert not d.set_config(0x04)
    assert not d.assign_id(7)
    assert not d.set_origin()
    assert not d.set_wave_frequency(5)
    assert d.eeprom.writes == writes and d.drive_id == 1
    assert d.read_config().to_byte() == 0
    d.reset()  # the power cycle clears it (6.1); then everything is accepted again
    assert d.set_param("main_gain", 60) and d.get_param("main_gain") == 60


def test_6_1_both_front_ends_ignore_writes_during_an_alarm_and_answer_reads() -> None:
    drive232 = VirtualDrive(1)
    line = Dyn232Line([drive232])
    drive232.trip(AlarmCode.LOST_PHASE)
    assert line.receive(c232.encode(1, H.SET_MAIN_GAIN, 60)) == b""
    assert line.receive(c232.encode(1, DmmFunction.SET_DRIVE_CONFIG, 0x04)) == b""
    (reply,) = c232.Framer().feed(line.receive(c232.encode(1, H.READ_MAIN_GAIN, 0)))
    assert isinstance(reply, c232.Packet) and reply.value == drive232.get_param("main_gain") != 60
    assert drive232.read_config().to_byte() == 0

    drivecan = VirtualDrive(2)
    net = DynCanNetwork([drivecan])
    drivecan.trip(AlarmCode.OVERHEAT)
    net.take_outbox()
    before = drivecan.get_param("main_gain")
    assert net.handle(ccan.request(2, F.SET_PARAM_GROUP1, fields=(60, 0, 0, 0))) == []
    assert net.handle(ccan.request(2, DmmFunction.SET_DRIVE_CONFIG, 0x04)) == []
    assert net.handle(ccan.request(2, F.GO_ABSOLUTE_POS_SYNC, 1000)) == []
    (group,) = net.handle(ccan.request(2, F.READ_PARAM_GROUP1))
    assert group.fields()[0] == before
    # data outside the manual's ranges is still answered Drive Error 0xFF (the frame check)
    (err,) = net.handle(ccan.request(2, F.SET_PARAM_GROUP1, fields=(128, 0, 0, 0)))
    assert err.data == bytes((ccan.DriveErrorCode.INVALID_DATA,))
    drivecan.reset()
    assert net.handle(ccan.request(2, F.SYNC_TRIGGER, ccan.SyncTrigger.ABSOLUTE)) == []
    drivecan.advance(0.5)
    assert drivecan.position == 0  # the load sent during the alarm was ignored
