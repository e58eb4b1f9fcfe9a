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
* Loop gains (5.2), each over its whole register range, onto the engine's loop
  (docs/tuning.md): position kp 0x07 / 15 = position gain in 1/s (60 -> 4, default 1500 ->
  100, 30000 -> 2000); speed kp 0x05 x 0.8 = speed loop bandwidth on the bare rotor in
  rad/s (0 -> none, default 1000 = 1.0 -> 800, 10000 -> 8000); integration time 0x06 (ms) ->
  integrator zero 1000 / time rad/s (2 -> 500, default 20 -> 50), and 2000 ms none at all
  (4.4: 2000 "cancels" integration). The torque filter is the DMM default (a = 3302 rad/s).
* A plain cascade: no velocity or acceleration feed-forward, so the following error at a
  constant speed is speed / position gain. The encoder counts 32,768 per revolution.
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
FRICTION_FRACTION = 0.002  # Coulomb friction / rated torque
NO_CURVE_ACCEL_RPM_S = 1_000_000.0
ENGINE_PARAM_MIN, ENGINE_PARAM_MAX = 1, 127  # the engine's gain and torque-limit scale
POSITION_KP_PER_RAD_S = 15.0  # 0x07 units per 1/s of position gain
SPEED_BW_PER_SPEED_KP = 0.8  # rad/s of speed loop bandwidth per 0x05 unit
NO_INTEGRATION_MS = 2000  # 0x06 at its top: no integral action (4.4)
TORQUE_FILTER_RAD_S = 26.0 * 127  # no TrqCons register: the DMM default filter


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


def loop_coefficients(position_kp: int, speed_kp: int, integration_ms: int
                      ) -> tuple[float, float, float, float]:
    """The engine's (position gain 1/s, speed bandwidth rad/s, integrator zero rad/s, torque
    filter rad/s) for registers 0x07, 0x05 and 0x06."""
    integ = 0.0 if integration_ms >= NO_INTEGRATION_MS else 1000.0 / max(1, integration_ms)
    return (position_kp / POSITION_KP_PER_RAD_S, speed_kp * SPEED_BW_PER_SPEED_KP, integ,
            TORQUE_FILTER_RAD_S)


def torque_limit_param(limit_a: float, peak_a: float) -> int:
    """The engine's torque limit (127 = peak current) for a current limit in amperes."""
    return _engine_param(limit_a / peak_a * ENGINE_PARAM_MAX)


def profile(target_speed: int, acceleration: int, max_rpm: float) -> tuple[float, float]:
    """(speed rpm, acceleration rpm/s) of the drive's curve: the model caps the speed (1)."""
    accel = (float(acceleration) if yzaim.uses_internal_profile(acceleration)
             else NO_CURVE_ACCEL_RPM_S)
    return min(float(target_speed), max_rpm), accel
