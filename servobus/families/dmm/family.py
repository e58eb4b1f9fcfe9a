"""The DMM DYN2 / DC2 / DYN4 family as the vendor-neutral Axis sees it (docs/axis.md).

Units at the Axis: positions in encoder counts (65,536 per revolution), speed in rpm,
current in amperes. A point-to-point command moves ``command x 4096 / GEAR_NUM x 4``
counts (DYN2 manual 7.4.1), so the Axis converts counts to command units through the
GEAR_NUM it reads from the drive: ``command = round(counts x GEAR_NUM / 16384)``, rounded
half away from zero; the resolution is ``16384 / GEAR_NUM`` counts (4 at GEAR_NUM 4096).
"""

from __future__ import annotations

from servobus.axis.capabilities import Capability
from servobus.axis.types import (
    AxisStatus,
    Family,
    GainRole,
    Persistence,
    TuningGain,
    TuningProfile,
    motion_state,
)
from servobus.axis.units import round_counts
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.families.dmm.profile import PTP
from servobus.families.dmm.registers import AlarmCode, DriveStatus

ALARM_TEXT: dict[int, str] = {
    AlarmCode.LOST_PHASE: "lost phase (|Pset - Pmotor| > 180 deg, or >= 90 deg for 2 s)",
    AlarmCode.OVER_CURRENT: "over current",
    AlarmCode.OVERHEAT: "overheat / over power",
    AlarmCode.CHECKSUM: "bad checksum (command refused)",
    AlarmCode.OVER_VOLTAGE: "over voltage",
}

#: What the DMM Axis (families/dmm/axis.py) can do beyond move/speed/stop/params, on any
#: protocol (servobus.axis.capabilities).
CAPABILITIES = frozenset({
    Capability.WAVES, Capability.CONFIG, Capability.ORIGIN, Capability.DRIVE_ID,
    Capability.RESET, Capability.COMMAND_UNITS, Capability.STREAM_TARGETS, Capability.TUNING,
    Capability.HOMING,
})

#: The tuner's gains (manual 5.1, 5.2); every write goes to EEPROM (5.1).
TUNING = TuningProfile(
    gains=(TuningGain(GainRole.POSITION, "main_gain"), TuningGain(GainRole.SPEED, "speed_gain"),
           TuningGain(GainRole.INTEGRAL, "int_gain"), TuningGain(GainRole.FILTER, "trq_cons")),
    persistence=Persistence.EEPROM_EACH_WRITE,
    save_hint="written to the drive's EEPROM as they were set (manual 5.1)",
    learns_load=True,  # Adaptive Tuning (5.2)
)

DYN2 = Family(
    name="dmm-dyn2",
    title="DMM DYN2/DC2/DYN4",
    counts_per_rev=U.COUNTS_PER_REV,
    params=tuple(p.info for p in P.PARAMS),
    capabilities=CAPABILITIES,
    ptp_profile=PTP,
    alarms={int(k): v for k, v in ALARM_TEXT.items()},
    wave_counts_per_unit=U.WAVE_COUNTS_PER_UNIT,
    tuning=TUNING,
)


def axis_status(status: DriveStatus, raw: int | None = None,
                speed_rpm: float | None = None) -> AxisStatus:
    """The DYN2 status byte (7.3) and the measured speed as the one AxisStatus.

    b5 (motion busy) covers the built-in S-curve/linear/circular profiles only, and b0 (on
    position) compares Pset with Pmotor, which a constant-speed or analog-speed reference
    drags along: so the speed decides ``moving`` when no profile runs (motion_state).
    """
    code = int(status.alarm)
    moving, in_position = motion_state(status.motion_busy, status.on_position, speed_rpm)
    return AxisStatus(
        enabled=not status.servo_free,
        moving=moving,
        in_position=in_position,
        alarm_code=code,
        alarm_text=DYN2.alarm_text(code),
        alarm_latched=status.alarm.latching,
        raw=int(status.to_byte()) if raw is None else raw,
        family=DYN2.name,
        vendor=status,
    )


def counts_to_command(counts: int, gear_num: int) -> int:
    """Encoder counts -> point-to-point command units at ``gear_num`` (rounded, see module)."""
    return round_counts(U.counts_to_command(counts, gear_num))


def command_to_counts(command: int, gear_num: int) -> int:
    return round_counts(U.command_to_counts(command, gear_num))
