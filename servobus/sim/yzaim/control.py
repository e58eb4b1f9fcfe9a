"""Control channel of the virtual YZ-AIM motors: the world around a motor on a machine.

The same channel as the DMM drives' (:mod:`servobus.sim.core.control`, JSON lines over
:mod:`servobus.sim.control_server`, ``servobus sim control``), with the YZ-AIM's own table:
what a machine does around an integrated motor - its supply, the multi-turn battery, a load,
a blocked shaft - and the motor's internal state. A motor is addressed by its device address
(register 0x15, as it answers on the bus). ``servobus sim easycan --control`` and ``servobus
sim modbus --control`` serve it; docs/sim-control.md lists every command.

Units: positions in YZ-AIM counts (32,768 per revolution), speed rpm, current A, supply V,
torque N m, inertia kg m^2, time s. Sections are the YZ-AIM manual's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from servobus.sim.core import control as channel
from servobus.sim.core.control import Arg, ChannelControl, Reply, apply_load, ok
from servobus.sim.yzaim import physics as phys
from servobus.sim.yzaim.motor import OVER_VOLTAGE_MARGIN, YzaimMotor

Command = channel.Command[YzaimMotor]
MAX_SUPPLY_V = 200.0
SURGE_FACTOR = 1.2  # the over_voltage fault's default: 20 % above the model's top supply


@dataclass(frozen=True)
class Fault:
    name: str
    args: tuple[Arg, ...]
    inject: Callable[[YzaimMotor, dict[str, Any]], None]
    doc: str


def motor_state(m: YzaimMotor) -> Reply:
    """The motor's internal state (positions in counts of 32,768 per revolution)."""
    alarm = m.alarm
    return {
        "time_s": round(m.time, 6),
        "model": m.model.name,
        "alarm": alarm.name,
        "alarm_code": alarm.code,
        "enabled": m.enabled,
        "speed_mode": m.speed_mode,
        "position": m.position,
        "target": m.target,
        "following_error": round(m.drive.position_error / phys.CORE_PER_COUNT, 3),
        "speed_rpm": round(m.speed_rpm, 3),
        "current_a": round(m.current_a, 4),
        "world": m.world(),
    }


def _alarm(m: YzaimMotor) -> Reply:
    return ok(alarm=m.alarm.name, alarm_code=m.alarm.code)


def nominal_supply_v(m: YzaimMotor) -> float:
    """The middle of the model's supply range (what the simulator powers a motor with)."""
    low, high = m.model.supply_v
    return (low + high) / 2


def _state(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    return ok(**motor_state(m))


def _bus(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    m.set_supply_voltage(a["volts"])
    return _alarm(m)


def _battery(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    m.set_battery(a["ok"])
    return _alarm(m)


def _load(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    return apply_load(m, m.drive, a)


def _fault(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    fault = FAULTS[a["fault"]]
    fault.inject(m, a)
    return ok(fault=fault.name, alarm=m.alarm.name, alarm_code=m.alarm.code)


def _clear(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    """Remove the causes (not a latched alarm: 0x01 = 0 or a power cycle clears it, 2.3)."""
    m.set_blocked(False)
    m.set_disturbance(0.0)
    m.set_battery(True)
    m.set_supply_voltage(nominal_supply_v(m))
    return _alarm(m)


def _power_cycle(ctl: MotorControl, m: YzaimMotor, a: dict[str, Any]) -> Reply:
    m.power_cycle()
    return ok(position=m.position, alarm=m.alarm.name)


def _over_voltage(m: YzaimMotor, a: dict[str, Any]) -> None:
    volts = a["volts"] if a["volts"] is not None else m.model.supply_v[1] * SURGE_FACTOR
    m.set_supply_voltage(volts)


FAULTS: dict[str, Fault] = {f.name: f for f in (
    Fault("over_voltage", (Arg("volts", float, 0.0, MAX_SUPPLY_V, default=None,
                               doc=f"supply voltage (trips above the model's range + "
                                   f"{OVER_VOLTAGE_MARGIN - 1:.0%}) [default: "
                                   f"{SURGE_FACTOR - 1:.0%} above the range]"),),
          _over_voltage, "a supply surge: over-voltage alarm 0x12 at once; the supply stays "
          "until `bus` or `clear`"),
    Fault("battery", (), lambda m, a: m.set_battery(False),
          "the multi-turn battery flat: warning 0x13 (57AIM only), the motor keeps running"),
    Fault("stall", (), lambda m, a: m.set_blocked(True),
          "the shaft blocked: stall alarm 0x14 once the motor pushes at its standstill limit "
          "for 0x18's units digit in seconds (2.3)"),
    Fault("load_step", (Arg("torque_nm", float, -100.0, 100.0, doc="external torque, + = CW"),),
          lambda m, a: m.set_disturbance(a["torque_nm"]),
          "a load torque step on the shaft (stays until `clear` or `load`)"),
    Fault("inertia", (Arg("kgm2", float, 0.0, 10.0, doc="load inertia at the motor shaft"),),
          lambda m, a: m.set_load(inertia=a["kgm2"]), "the load inertia changes"),
    Fault("power_cycle", (), lambda m, a: m.power_cycle(),
          "power off and on: clears a latched alarm; a multi-turn model keeps its position"),
)}

COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("ping", (), None, "the motor addresses, commands and faults", changes=False,
            run_channel=channel.ping),
    Command("state", (), _state, "internal state: position, error, speed, current, alarm",
            changes=False),
    Command("bus", (Arg("volts", float, 0.0, MAX_SUPPLY_V,
                        doc="supply voltage (over-voltage above the range + 10 %)"),),
            _bus, "set the supply voltage"),
    Command("battery", (Arg("ok", bool, doc="false: the multi-turn battery is flat"),),
            _battery, "the multi-turn backup battery (warning 0x13 when flat)"),
    *channel.world_commands(FAULTS, _load, _fault),
    Command("clear", (), _clear, "remove every fault cause (not a latched alarm)"),
    Command("power_cycle", (Arg("off_s", float, 0.0, 0.0, default=0.0,
                                doc="0 only: the motor powers off and on at once"),),
            _power_cycle, "power off and on: RAM from EEPROM, clears a latched alarm"),
)}


class MotorControl(ChannelControl[YzaimMotor]):
    """Executes control requests on a set of YZ-AIM motors, addressed by device address."""

    commands: Mapping[str, Command] = COMMANDS
    faults = FAULTS

    def drive_id(self, drive: YzaimMotor) -> int:
        return drive.address
