"""The DMM DYN5 (EtherNet/IP option) as the vendor-neutral Axis sees it (docs/enip.md).

Built on the one instance table, :mod:`servobus.families.dyn5.params` (DYN5 EtherNet/IP
Specification 1.1A, sections 4.3/4.4). What this module adds:

* **Parameters** in the Axis's names: the drive parameters keep the names the other DMM
  families use (``main_gain`` ... ``torque_limit``: the instance entry's ``param``), so a
  backup, ``servobus set max_speed 40`` or a GUI means the same thing on a DYN2 and a DYN5;
  the EtherNet/IP module's own settable values keep their instance names (``memory_test``,
  ``torque_speed_limit``). Ranges and units are the DYN5's (4.3: GEAR_NUM 1..16384,
  LINE_NUM 1..4095), not the DYN2's. Every Parameter-object write is RAM only (4.1), so
  every ParamInfo is ``Storage.RAM``. Commands and modes (enable, reset, origin, command
  mode, motion) are Axis calls, not parameters.
* **Status**: the DYN5 status word (4.4, instance 0x02 and input word 3): b0 off position,
  b1 servo free, b4..b2 alarm code (1 lost phase, 2 over current, 3 overheat/over power,
  4 CRC error, 5 over voltage), b5 S-curve running. Codes 6 and 7 are undefined in the
  manual: reported as "alarm 6"/"alarm 7" rather than folded into another code. Code 4 is
  a refusal notice like the DYN2's checksum code, not a latched alarm; every other code
  latches (the drive frees the motor until Reset or power cycle).
* **Counts**: 65,536 per revolution (the 16-bit encoder of the manual's examples, 4.4 0x1D
  and 6.3). A point-to-point command moves ``command x 4096 / GEAR_NUM x 4`` counts
  (Appendix B), so the Axis converts counts through GEAR_NUM as on the DYN2.

Decision: a DYN5 with a 20-bit encoder reads 1,048,576 counts per revolution (4.4, 0x1D);
the manual gives no profile formula for it, so servobus models the 16-bit encoder only.
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
from servobus.families.dmm import params as dmm_params
from servobus.families.dmm import units as U
from servobus.families.dmm.profile import PTP
from servobus.families.dmm.registers import ALARM_SHIFT, AlarmCode, StatusBits
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.params import Instance, Kind

NAME = "dmm-dyn5"

ALARM_TEXT: dict[int, str] = {
    1: "lost phase (|Pset - Pmotor| > 8192 counts, 180 deg)",
    2: "over current",
    3: "overheat / over power",
    4: "CRC error: command refused",
    5: "over voltage",
}
#: Alarm codes that do not latch (a one-read notice, like the DYN2 checksum code).
NOTICE_CODES = frozenset({int(AlarmCode.CHECKSUM)})

#: What the DYN5 Axis can do (servobus.axis.capabilities): square/sine waves
#: (0x0F/0x11/0x13), the multi-turn absolute origin (0x03), Reset (0x21), torque mode
#: (0x25/0x26/0x27), cyclic I/O (section 5), the power-cleared marker cell, raw command
#: units and streamed targets (the DMM profile). No config byte and no drive id: a DYN5 is
#: addressed by its IP address (manual 2, 3.1).
CAPABILITIES = frozenset({
    Capability.WAVES, Capability.ORIGIN, Capability.RESET, Capability.TORQUE_MODE,
    Capability.CYCLIC_IO, Capability.POWER_LOSS_DETECTION, Capability.COMMAND_UNITS,
    Capability.STREAM_TARGETS, Capability.TUNING,
})


def _param_name(inst: Instance) -> str:
    return inst.param or inst.name


def _default(inst: Instance) -> int:
    if inst.param is not None:
        return dmm_params.spec(inst.param).default
    return inst.default


def _info(inst: Instance) -> ParamInfo:
    assert inst.minimum is not None and inst.maximum is not None
    return ParamInfo(_param_name(inst), inst.minimum, inst.maximum, _default(inst), inst.unit,
                     Storage.RAM, f"{inst.meaning} (instance 0x{inst.number:02X})")


#: Settable values, in instance order: the drive parameters, then the EtherNet/IP module's
#: stored values (RW instances that are not commands).
SETTABLE: tuple[Instance, ...] = tuple(
    i for kind in (Kind.PARAMETER, Kind.STORED) for i in dyn5.INSTANCES
    if i.kind is kind and i.access is dyn5.Access.RW)
#: Axis parameter name -> its Parameter instance (the one mapping the client uses).
PARAM_INSTANCES: dict[str, Instance] = {_param_name(i): i for i in SETTABLE}
PARAM_NAMES: tuple[str, ...] = tuple(PARAM_INSTANCES)

#: The tuner's gains (Pr.00 - Pr.03). Writes over EtherNet/IP reach RAM only, and the link
#: has no save ("settings lost after Reset command or Power Cycle"): DMMDRV5 keeps them.
TUNING = TuningProfile(
    gains=(TuningGain(GainRole.POSITION, "main_gain"), TuningGain(GainRole.SPEED, "speed_gain"),
           TuningGain(GainRole.INTEGRAL, "int_gain"), TuningGain(GainRole.FILTER, "trq_cons")),
    persistence=Persistence.RAM_ONLY,
    save_hint="lost at reset or power cycle: enter these gains in DMMDRV5 to keep them",
)

DYN5 = Family(
    name=NAME,
    title="DMM DYN5",
    counts_per_rev=U.COUNTS_PER_REV,
    params=tuple(_info(i) for i in SETTABLE),
    capabilities=CAPABILITIES,
    alarms=ALARM_TEXT,
    wave_counts_per_unit=U.WAVE_COUNTS_PER_UNIT,
    ptp_profile=PTP,
    tuning=TUNING,
)


@dataclass(frozen=True)
class Dyn5Status:
    """The DYN5 status word decoded bit by bit (``AxisStatus.vendor``)."""

    on_position: bool
    servo_free: bool
    alarm: int
    motion_busy: bool

    @classmethod
    def from_word(cls, word: int) -> Dyn5Status:
        return cls(on_position=not word & StatusBits.OFF_POSITION,
                   servo_free=bool(word & StatusBits.SERVO_FREE),
                   alarm=(word & StatusBits.ALARM_MASK) >> ALARM_SHIFT,
                   motion_busy=bool(word & StatusBits.MOTION_BUSY))

    def as_dict(self) -> dict[str, object]:
        return {"on_position": self.on_position, "servo_free": self.servo_free,
                "alarm": self.alarm, "motion_busy": self.motion_busy}


def axis_status(word: int, speed_rpm: float | None = None) -> AxisStatus:
    """The DYN5 status word (instance 0x02, input image word 3) and the measured speed
    (instance 0x1E, input image word 2) as the one AxisStatus (motion_state: the busy bit
    covers the built-in profiles only, so the speed decides ``moving`` otherwise)."""
    st = Dyn5Status.from_word(word)
    moving, in_position = motion_state(st.motion_busy, st.on_position, speed_rpm)
    return AxisStatus(
        enabled=not st.servo_free,
        moving=moving,
        in_position=in_position,
        alarm_code=st.alarm,
        alarm_text=DYN5.alarm_text(st.alarm),
        alarm_latched=st.alarm != 0 and st.alarm not in NOTICE_CODES,
        raw=word,
        family=NAME,
        vendor=st,
    )
