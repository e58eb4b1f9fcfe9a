"""Unit factors and drive models (DYN2 manual 4.x, 7.4.1; DYN CAN 6; DYN5 Appendix B).

Every conversion factor lives here once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from servobus.errors import ArgumentRangeError

COUNTS_PER_REV = 65_536  # 16-bit absolute encoder; position readouts are in these counts
ONRANGE_UNITS_PER_REV = 16_384  # OnRange and the lost-phase threshold count in 1/16384 rev
LOST_PHASE_UNITS = 8_192  # 180 deg in 1/16384 rev
GEAR_BASE = 4_096  # gear ratio = 4096 / GEAR_NUM
SPEED_FACTOR_RPM = 12.21  # (MaxSpd+3)^2 / 16 * 12.21 rpm
ACCEL_FACTOR_RPM_S = 635.78  # MaxAcl * 635.78 rpm/s
PARAM_MAX = 127  # Max Speed and Max Accel: 1..127 (5.1)
SOFT_START_K = 59.98  # speed-mode 10-90 % rise time = 59.98 / MaxAcl^2 s
WAVE_COUNTS_PER_UNIT = COUNTS_PER_REV / 8_192  # wave amplitude 4096 = 180 deg
ANALOG_SPEED_RPM_PER_V = 600.0  # +5 V = 3000 rpm
ANALOG_POSITION_DEG_AT_10V = 90.0  # x 4096 / GEAR_NUM
OVER_VOLTAGE_V = 80.0
DYN232_TORQUE_UNITS_PER_A = 1000.0  # General_Read torque on DYN232M: mA (servobus decision)
CAN_TORQUE_FULL_SCALE = 700  # DYN CAN General_Read torque: 700 = peak current
DYN5_TORQUE_FULL_SCALE = 2000  # DYN5: 2000 = 100 % peak current


def gear_ratio(gear_num: int) -> float:
    return GEAR_BASE / gear_num


def profile_speed_rpm(max_speed: int, gear_num: int = GEAR_BASE) -> float:
    """Point-to-point cruise speed (7.4.1): (MaxSpd+3)^2/16 x 12.21 x ratio."""
    return (max_speed + 3) ** 2 / 16 * SPEED_FACTOR_RPM * gear_ratio(gear_num)


def profile_accel_rpm_s(max_accel: int, gear_num: int = GEAR_BASE) -> float:
    """Point-to-point acceleration (7.4.1): MaxAcl x 635.78 x ratio."""
    return max_accel * ACCEL_FACTOR_RPM_S * gear_ratio(gear_num)


def stream_profile(max_speed: int, max_accel: int, gear_num: int) -> tuple[float, float]:
    """A position target's motor speed and acceleration, (rpm, rpm/s): the point-to-point
    profile (7.4.1) a target update (DTPU) runs at; both are EEPROM parameters."""
    return profile_speed_rpm(max_speed, gear_num), profile_accel_rpm_s(max_accel, gear_num)


def profile_params(rpm: float | None, accel_rpm_s: float | None,
                   gear_num: int) -> dict[str, int]:
    """``max_speed``/``max_accel`` for a point-to-point profile (7.4.1) at GEAR_NUM (None:
    leave it out). Decision: Max Speed is the smallest value whose cruise is at least
    ``rpm``, so a lease at that speed stays inside the profile (a step of (v+3)^2 is about
    7 % at v = 25); Max Accel the largest whose acceleration is at most ``accel_rpm_s``
    (at least 1, at most 127): never harder than asked. A speed above Max Speed 127's is
    ArgumentRangeError."""
    values: dict[str, int] = {}
    ratio = gear_ratio(gear_num)
    if rpm is not None:
        top = profile_speed_rpm(PARAM_MAX, gear_num)
        if rpm > top:
            raise ArgumentRangeError(f"{rpm:g} rpm is above the fastest profile the drive runs "
                                     f"at GEAR_NUM {gear_num} ({top:g} rpm, max_speed "
                                     f"{PARAM_MAX})")
        v = max(1, math.ceil(math.sqrt(rpm * 16 / (SPEED_FACTOR_RPM * ratio)) - 3))
        while v > 1 and profile_speed_rpm(v - 1, gear_num) >= rpm:  # float edges
            v -= 1
        while profile_speed_rpm(v, gear_num) < rpm:
            v += 1
        values["max_speed"] = v
    if accel_rpm_s is not None:
        values["max_accel"] = min(PARAM_MAX,
                                  max(1, math.floor(accel_rpm_s / (ACCEL_FACTOR_RPM_S * ratio))))
    return values


def command_to_counts(command: float, gear_num: int = GEAR_BASE) -> float:
    """Motor movement for a point-to-point command: command x ratio x 4 counts."""
    return command * gear_ratio(gear_num) * 4


def counts_to_command(counts: float, gear_num: int = GEAR_BASE) -> float:
    return counts / (gear_ratio(gear_num) * 4)


def pulses_per_rev(gear_num: int) -> int:
    """Pulse-train inputs: 4 x GEAR_NUM pulses per revolution."""
    return 4 * gear_num


def soft_start_rise_s(max_accel: int) -> float:
    """Speed-mode soft start, 10 %->90 % rise time."""
    return SOFT_START_K / max_accel**2


def onrange_to_counts(units: float) -> float:
    return units * COUNTS_PER_REV / ONRANGE_UNITS_PER_REV


def rpm_to_counts_per_s(rpm: float) -> float:
    return rpm * COUNTS_PER_REV / 60.0


def counts_per_s_to_rpm(cps: float) -> float:
    return cps * 60.0 / COUNTS_PER_REV


@dataclass(frozen=True)
class MotorModel:
    """Drive + motor combination the virtual drive simulates.

    Peak currents are from the DYN2 manual (1.1, 4.3). Mechanical figures are servobus
    choices for DMM's matching 200 W / 750 W motors, documented as such.
    """

    name: str
    peak_current_a: float
    torque_per_volt_a: float  # torque-mode analog scaling (A per V)
    rated_current_a: float  # continuous current for the I^2 t model
    torque_constant_nm_a: float
    rotor_inertia_kgm2: float
    friction_nm: float
    max_speed_rpm: float


MODELS: dict[str, MotorModel] = {
    "DYN2-T1": MotorModel("DYN2-T1", 10.0, 1.0, 3.3, 0.25, 1.6e-5, 0.001, 5000.0),
    "DYN2-TL": MotorModel("DYN2-TL", 20.0, 2.0, 6.6, 0.36, 1.1e-4, 0.002, 5000.0),
}
DEFAULT_MODEL = "DYN2-TL"
