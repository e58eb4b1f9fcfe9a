"""The control channel of the virtual YZ-AIM motors (servobus.sim.yzaim.control), in-process
on simulated time: each command and fault, with the alarm the YZ-AIM manual gives (2.3) as a
host reads it from register 0x0E; the refusals of the shared protocol."""

from __future__ import annotations

import pytest

from servobus.families.yzaim import registers as Y
from servobus.sim.core.control import ControlError
from servobus.sim.core.loads import PRESETS
from servobus.sim.yzaim.control import COMMANDS, FAULTS, MotorControl
from servobus.sim.yzaim.motor import YzaimMotor

pytestmark = pytest.mark.timeout(30)
ABS = Y.PAIR_BY_NAME["absolute_position"].low
ALARM = Y.BY_NAME["alarm_code"].address


def bench(*addresses: int) -> tuple[MotorControl, list[YzaimMotor]]:
    motors = [YzaimMotor(a) for a in addresses]
    return MotorControl(motors), motors


def move_to(m: YzaimMotor, counts: int) -> None:
    m.write_words(ABS, [counts & 0xFFFF, (counts >> 16) & 0xFFFF])


def test_ping_names_the_addresses_commands_and_faults() -> None:
    ctl, _ = bench(1, 7)
    reply = ctl.call("ping")
    assert reply["ids"] == [1, 7]
    assert reply["commands"] == sorted(COMMANDS) and reply["faults"] == sorted(FAULTS)


def test_state_shows_a_move_in_yzaim_counts() -> None:
    ctl, (m,) = bench(3)
    move_to(m, 2 * Y.COUNTS_PER_REV)
    m.advance(0.05)
    moving = ctl.state()
    assert moving["id"] == 3 and moving["model"] == m.model.name
    assert moving["enabled"] and moving["alarm"] == "none" and moving["alarm_code"] == 0
    assert moving["speed_rpm"] > 100 and moving["target"] == 2 * Y.COUNTS_PER_REV
    assert 0 < moving["position"] < 2 * Y.COUNTS_PER_REV
    m.advance(2.0)
    assert ctl.state()["position"] == pytest.approx(2 * Y.COUNTS_PER_REV, abs=10)


def test_a_supply_surge_trips_over_voltage_until_enable_is_cycled() -> None:
    """2.3 / 1: above the model's supply range (57AIM30C: 24-36 V; trips above +10 %)."""
    ctl, (m,) = bench(1)
    assert ctl.call("bus", volts=36.0)["alarm"] == "none"  # the top of the range
    reply = ctl.fault(None, "over_voltage")  # 20 % above: 43.2 V
    assert reply["alarm"] == "over_voltage" and m.read_word(ALARM) == 0x12
    assert ctl.state()["world"]["supply_v"] == pytest.approx(43.2)
    assert not ctl.state()["enabled"]
    assert ctl.call("clear")["alarm"] == "over_voltage"  # the cause goes, the alarm stays
    m.write_words(Y.BY_NAME["output_enable"].address, [0])  # 2.3: "downtime"
    assert ctl.state()["alarm"] == "none"


def test_a_flat_battery_warns_and_the_motor_keeps_running() -> None:
    ctl, (m,) = bench(1)
    assert ctl.fault(None, "battery")["alarm"] == "battery_warning"
    assert m.read_word(ALARM) == 0x13
    move_to(m, Y.COUNTS_PER_REV)
    m.advance(1.0)
    assert ctl.state()["position"] == pytest.approx(Y.COUNTS_PER_REV, abs=10)
    assert ctl.call("battery", ok=True)["alarm"] == "none"


def test_a_blocked_shaft_stalls_after_the_units_digit_of_0x18() -> None:
    """2.3 stall 0x14: the default 0x18 = 303 gives 3 s at the standstill limit."""
    ctl, (m,) = bench(1)
    ctl.fault(None, "stall")
    move_to(m, Y.COUNTS_PER_REV)
    m.advance(2.5)
    assert ctl.state()["alarm"] == "none"
    assert ctl.state()["following_error"] > Y.COUNTS_PER_REV / 2
    m.advance(1.0)
    assert ctl.state()["alarm"] == "stall" and m.read_word(ALARM) == 0x14
    ctl.call("clear")
    assert not ctl.state()["world"]["blocked"]


def test_load_and_load_step_show_in_the_state_and_the_current() -> None:
    ctl, (m,) = bench(1)
    reply = ctl.call("load", inertia=30.0, friction=0.01, torque_nm=0.2)  # 30 x the rotor
    world, mechanics = reply["world"], reply["mechanics"]
    assert world["load_inertia_kgm2"] == pytest.approx(30 * m.drive.model.rotor_inertia_kgm2)
    assert world["load_torque_nm"] == 0.2 and mechanics["inertia"] == pytest.approx(30.0)
    reply = ctl.call("load", load="belt", load_torque=0.05)  # the keys of sim:// URLs
    assert reply["mechanics"]["resonance"] == PRESETS["belt"].resonance
    assert reply["mechanics"]["load_torque"] == 0.05
    m.advance(0.5)
    assert ctl.state()["current_a"] < -0.5  # holding against +0.2 N m (0.218 N m/A)
    ctl.fault(None, "load_step", torque_nm=-0.2)
    m.advance(0.5)
    assert ctl.state()["current_a"] > 0.5


def test_a_power_cycle_keeps_the_multi_turn_position_and_clears_the_alarm() -> None:
    ctl, (m,) = bench(1)
    move_to(m, 3 * Y.COUNTS_PER_REV)
    m.advance(2.0)
    ctl.fault(None, "over_voltage")
    ctl.call("bus", volts=30.0)
    reply = ctl.call("power_cycle")
    assert reply["alarm"] == "none"
    assert reply["position"] == pytest.approx(3 * Y.COUNTS_PER_REV, abs=10)


def test_refusals_name_the_problem() -> None:
    ctl, _ = bench(1, 2)
    cases = [({"cmd": "state"}, "unknown_id"), ({"cmd": "state", "id": 9}, "unknown_id"),
             ({"cmd": "analog", "id": 1, "volts": 1}, "unknown_command"),
             ({"cmd": "bus", "id": 1, "volts": 500}, "bad_argument"),
             ({"cmd": "power_cycle", "id": 1, "off_s": 1}, "bad_argument"),
             ({"cmd": "fault", "id": 1, "fault": "over_current"}, "bad_argument"),
             ({"cmd": "fault", "id": 1, "fault": "load_step"}, "bad_argument"), ([], "malformed")]
    for request, kind in cases:
        reply = ctl.execute(request)
        assert reply["ok"] is False and reply["kind"] == kind, (request, reply)
    with pytest.raises(ControlError):
        ctl.call("battery", 1)
