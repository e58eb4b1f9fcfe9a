"""YZ-AIM integrated servos as the vendor-neutral Axis sees them (docs/yzaim.md).

Built on the one register table, :mod:`servobus.families.yzaim.registers` (YZ-AIM EasyCan v3.5
manual, 5.2). What this module adds:

* **Parameters**: the settings among the registers, under the table's snake_case names
  (``target_speed``, ``acceleration``, ``position_loop_kp``, ``max_current`` ...), in raw
  register units (the ParamInfo unit says the scale: ``max_current`` in mA, ``speed_loop_kp``
  in 0.001, ``standstill_max_output`` in 0.1 %). Left out because they are Axis calls or
  motion, not settings: modbus_enable / output_enable (enable, disable), device_address
  (read_id, assign_id), the positions, the save flag, the position cache and sync_control.
  A write changes RAM only (Storage.RAM); the save flag 0x14 stores every saved register
  at once (the protocols' ``save_parameters()``), so a parameter loop never wears EEPROM.
* **Counts**: 32,768 per revolution, the 15-bit encoder (1); moves are in counts on the
  wire, no gear conversion (the gear acts on the pulse input only, 4.7).
* **Status**: YZ-AIM has no status word. The Axis reads output_enable 0x01, alarm_code 0x0E
  and motor_speed 0x10 (one 0x12 read on EasyCan) and, when it commanded a position,
  the position 0x16/0x17. Decisions (servobus.axis.types.motion_state, as on every
  family): *moving* = |speed| >= MOVING_RPM, or still more than the +-10 counts of 5.4a
  away from the last commanded target; *in position* = within those 10 counts of it (or
  no target commanded) and not moving; *enabled* = output_enable is 1 and
  no alarm stops the motor; a stopping alarm is latched (the motor stays stopped until
  output_enable is written 0 then 1, or the power is cycled); the battery warning is not.
"""

from __future__ import annotations

from dataclasses import dataclass

from servobus.axis.capabilities import Capability
from servobus.axis.types import (
    AxisStatus,
    Family,
    GainRole,
    ParamInfo,
    Persistence,
    Storage,
    TuningGain,
    TuningProfile,
    motion_state,
)
from servobus.families.yzaim import registers as yzaim

NAME = yzaim.FAMILY
#: Registers that are Axis calls or motion rather than settings (module docstring).
NOT_PARAMETERS = frozenset({"modbus_enable", "output_enable", "device_address",
                            "sync_control", "save_flag"})
#: What the YZ-AIM Axis can do (servobus.axis.capabilities): position clear (origin),
#: addressable ids, reset (output_enable 0 then 1 clears a latched alarm), streamed targets.
#: The synchronised start depends on the protocol (EasyCan's position caches).
CAPABILITIES = frozenset({
    Capability.ORIGIN, Capability.DRIVE_ID, Capability.RESET, Capability.STREAM_TARGETS,
    Capability.TUNING,
})

_UNITS: dict[str, str] = {
    "speed_loop_kp": "0.001",
    "speed_feedforward": "1/327 V/krpm",
    "standstill_max_output": "0.1 % (units digit: stall alarm s)",
    "max_current": "mA (units digit: over-current alarm s)",
}


def _unit(reg: yzaim.Register) -> str:
    return _UNITS.get(reg.name, reg.unit)


def _info(reg: yzaim.Register) -> ParamInfo:
    return ParamInfo(reg.name, reg.minimum, reg.maximum, reg.default, _unit(reg),
                     Storage.RAM, f"{reg.doc} (register 0x{reg.address:02X})")


#: Settable registers the Axis offers as parameters, in address order.
SETTABLE: tuple[yzaim.Register, ...] = tuple(
    r for r in yzaim.REGISTERS
    if r.access is yzaim.Access.RW and r.name not in NOT_PARAMETERS
    and r.address not in {a for p in yzaim.PAIRS for a in (p.low, p.high)})
PARAM_NAMES: tuple[str, ...] = tuple(r.name for r in SETTABLE)

#: The tuner's gains (5.2: 0x07, 0x05, 0x06). The units digits of the two kp are
#: configuration bits (pulse polarity, alarm output): a tuner keeps them. RAM until saved.
TUNING = TuningProfile(
    gains=(TuningGain(GainRole.POSITION, "position_loop_kp", keep_units_digit=True),
           TuningGain(GainRole.SPEED, "speed_loop_kp", keep_units_digit=True),
           TuningGain(GainRole.INTEGRAL, "speed_loop_integration_time", inverse=True)),
    persistence=Persistence.RAM_SAVE_COMMAND,
    save_hint="in RAM: saved with the save flag (register 0x14) only when asked (--save)",
)

YZAIM = Family(
    name=NAME,
    title="YZ-AIM",
    counts_per_rev=yzaim.COUNTS_PER_REV,
    params=tuple(_info(r) for r in SETTABLE),
    capabilities=CAPABILITIES,
    alarms={a.code: a.text for a in yzaim.ALARMS if a.code},
    tuning=TUNING,
)


@dataclass(frozen=True)
class YzaimStatus:
    """The registers a YZ-AIM status is made of (``AxisStatus.vendor``)."""

    output_enable: int
    alarm_code: int
    speed_rpm: float
    position_error: int | None  # counts from the commanded target; None: none commanded

    def as_dict(self) -> dict[str, object]:
        return {"output_enable": self.output_enable, "alarm_code": self.alarm_code,
                "speed_rpm": self.speed_rpm, "position_error": self.position_error}


def axis_status(output_enable: int, alarm_code: int, motor_speed_word: int,
                position_error: int | None = None) -> AxisStatus:
    """Registers 0x01, 0x0E, 0x10 (as read) and the distance to the commanded target."""
    speed = yzaim.BY_NAME["motor_speed"]
    rpm = speed.to_engineering(speed.from_word(motor_speed_word))
    found = yzaim.alarm(alarm_code)
    stops = alarm_code != 0 and found.stops_motor
    near = position_error is None or abs(position_error) <= yzaim.POSITION_TOLERANCE_COUNTS
    # The drive has no busy or on-position bit: a commanded target not yet reached is the
    # running profile, the +-10-count comparison (5.4a) the on-target test (motion_state).
    # A disabled motor (output_enable 0, or a stopping alarm) runs no profile, whatever
    # target it was given: off that target it is stopped, not "still moving" (issue 32).
    enabled = output_enable == 1 and not stops
    moving, in_position = motion_state(not near and enabled, near, rpm)
    return AxisStatus(
        enabled=enabled,
        moving=moving,
        in_position=in_position,
        alarm_code=alarm_code,
        alarm_text=YZAIM.alarm_text(alarm_code),
        alarm_latched=stops,
        raw=alarm_code,
        family=NAME,
        vendor=YzaimStatus(output_enable, alarm_code, rpm, position_error),
    )
