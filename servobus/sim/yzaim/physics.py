"""How a YZ-AIM motor maps onto the shared servo engine: motor sizing, gains, limits, units.

The YZ-AIM manual (section 1 model tables) gives rated torque, rated and maximum speed,
supply current and power per model, nothing about inertia, peak current or loop scaling.
Every number below that is not from those tables is a servobus decision (docs/yzaim.md):

* Motor current: the rated motor current is taken as the table's supply current (57AIM30C:
  4.4 A), so the torque constant is rated torque / that current (0.218 N*m/A). The peak is
  3x rated, capped at 10.009 A (the top of max_current 0x1D): 57AIM30C peaks at 10 A =
  2.18 N*m, 2.3x its rated torque.
* Rotor inertia 3e-5 kg*m^2 per N*m of rated torque (57AIM30C: 2.9e-5), Coulomb friction
  2 % of rated torque.
* Loop gains (5.2) onto the engine's scaling: position kp 0x07 / 37.5 = Main Gain (default
  1500 -> 40 -> 100 rad/s), speed kp 0x05 / 25 = Speed Gain (1000 = 1.0 -> 40 -> 400 rad/s),
  integration time 0x06 (ms) -> integrator zero 1000 / time rad/s (20 ms -> 50 rad/s; 2000
  ms is the engine's smallest integrator, as 4.4 says it "cancels" integration).
* Acceleration 0x03 >= 60000 (no internal curve, 4.1): the motor follows each new target at
  the speed limit with NO_CURVE_ACCEL_RPM_S, far above what the motor can do, so only its
  torque limit shapes the start.
"""

from __future__ import annotations

from servobus.families.dmm import units as U
from servobus.families.yzaim import registers as yzaim

#: Counts of the shared engine (65,536 per rev) per YZ-AIM count (32,768 per rev).
CORE_PER_COUNT = U.COUNTS_PER_REV / yzaim.COUNTS_PER_REV
PEAK_PER_RATED = 3.0
MAX_PEAK_A = yzaim.BY_NAME["max_current"].maximum / yzaim.BY_NAME["max_current"].per_unit
INERTIA_PER_NM = 3e-5  # kg*m^2 of rotor per N*m of rated torque
FRICTION_FRACTION = 0.02  # Coulomb friction / rated torque
NO_CURVE_ACCEL_RPM_S = 1_000_000.0
ENGINE_PARAM_MIN, ENGINE_PARAM_MAX = 1, 127  # the engine's gain and torque-limit scale
POSITION_KP_PER_MAIN_GAIN = 37.5
SPEED_KP_PER_SPEED_GAIN = 25.0
INT_GAIN_TIMES_MS = 200.0  # engine Integration Gain x 5 rad/s = 1000 / time_ms rad/s


def core_model(m: yzaim.MotorModel) -> U.MotorModel:
    """The engine's motor model for a YZ-AIM model of the manual's tables."""
    rated_a = m.current_a
    kt = m.torque_nm / rated_a
    return U.MotorModel(
        name=m.name,
        peak_current_a=min(PEAK_PER_RATED * rated_a, MAX_PEAK_A),
        torque_per_volt_a=1.0,  # no analog torque input on YZ-AIM
        rated_current_a=rated_a,
        torque_constant_nm_a=kt,
        rotor_inertia_kgm2=INERTIA_PER_NM * m.torque_nm,
        friction_nm=FRICTION_FRACTION * m.torque_nm,
        max_speed_rpm=float(m.max_rpm),
    )


def _engine_param(value: float) -> int:
    return max(ENGINE_PARAM_MIN, min(ENGINE_PARAM_MAX, round(value)))


def engine_gains(position_kp: int, speed_kp: int, integration_ms: int) -> dict[str, int]:
    """The engine's gain parameters for registers 0x07, 0x05 and 0x06."""
    return {
        "main_gain": _engine_param(position_kp / POSITION_KP_PER_MAIN_GAIN),
        "speed_gain": _engine_param(speed_kp / SPEED_KP_PER_SPEED_GAIN),
        "int_gain": _engine_param(INT_GAIN_TIMES_MS / max(1, integration_ms)),
    }


def torque_limit_param(limit_a: float, peak_a: float) -> int:
    """The engine's torque limit (127 = peak current) for a current limit in amperes."""
    return _engine_param(limit_a / peak_a * ENGINE_PARAM_MAX)


def profile(target_speed: int, acceleration: int, max_rpm: float) -> tuple[float, float]:
    """(speed rpm, acceleration rpm/s) of the drive's curve: the model caps the speed (1)."""
    accel = (float(acceleration) if yzaim.uses_internal_profile(acceleration)
             else NO_CURVE_ACCEL_RPM_S)
    return min(float(target_speed), max_rpm), accel
