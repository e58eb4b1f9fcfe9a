"""Constants of the virtual drive core: control rate, loop scaling, alarm thresholds.

Every number here is a servobus decision where the manuals are silent; the reason sits next
to it. Unit factors from the manuals live in :mod:`servobus.families.dmm.units`.
"""

from __future__ import annotations

from servobus.families.dmm import units as U

#: Fixed control period. 4 kHz: the torque filter pole (26 x 127 = 3302 rad/s) and a speed loop
#: of up to ~400 Hz are resolved (>= 2 samples per pole time constant), and 16 drives still fit
#: in half a core of pure Python (benchmarks/bench_core.py).
CONTROL_HZ = 4_000
CONTROL_DT = 1.0 / CONTROL_HZ

# ---------------------------------------------------------------- servo loop scaling
#: Position loop gain per Main Gain unit (1/s). Default 40 -> 100 rad/s.
KP_PER_MAIN_GAIN = 100.0 / 40
#: Speed loop bandwidth per Speed Gain unit on the bare rotor (rad/s). The speed loop torque gain
#: is rotor inertia x this x SpeedGain, so with load inertia J_L the bandwidth falls by
#: J_m / (J_m + J_L): a heavier load needs a larger Speed Gain (manual 5.1, 5.2). 20 rad/s
#: puts the light-load limit of the loop (its delay, filter and current loop) near Speed
#: Gain 100: at 127 the bare rotor buzzes near full torque, as 5.1 warns (docs/tuning.md).
SPEED_BW_PER_SPEED_GAIN = 20.0
#: Speed loop integrator zero per Integration Gain unit (rad/s). Default 20 -> 100 rad/s.
#: The defaults keep position : speed bandwidth at 1 : 8 with the zero well below crossover,
#: a well-damped step; raising Main Gain or Integration Gain towards the speed loop
#: bandwidth brings overshoot and ringing, as 5.2 warns.
KI_PER_INT_GAIN = 100.0 / 20
#: Manual 4.2: torque filter a/(s+a), a = 26 x TrqCons rad/s.
TORQUE_FILTER_PER_UNIT = 26.0

# ---------------------------------------------------------------- loop dynamics (docs/tuning.md)
#: The speed loop's torque command reaches the power stage this many periods later
#: (computation and PWM update of a digital drive).
TRANSPORT_DELAY_PERIODS = 2
#: Current loop bandwidth: a first-order lag behind the torque filter.
CURRENT_LOOP_HZ = 1_500.0
#: Adaptive Tuning (DYN2 5.2) as its result, not its algorithm: the drive's estimate of the
#: total inertia starts at the rotor's and moves towards the true one while the reference
#: accelerates, with this time constant (seconds of acceleration) ...
ADAPT_TAU_S = 0.25
#: ... and never beyond this multiple of the rotor inertia (a guard against a runaway
#: estimate; the manual states no limit, docs/tuning.md): above every load the project
#: simulates or benchmarks (inertia ratio 30), so those are learnt in full.
ADAPT_MAX_RATIO = 50.0

# ---------------------------------------------------------------- mechanics
#: Viscous friction as a fraction of the Coulomb friction per 1000 rpm.
VISCOUS_PER_1000RPM = 0.5
#: Compliant coupling: damping ratio when none is given, and the highest resonance the
#: integration at CONTROL_HZ resolves (semi-implicit Euler, omega x h < 1).
DEFAULT_DAMPING = 0.05
RESONANCE_MAX_HZ = 600.0
#: A compliant load's side has at least this Coulomb friction (its bearings), as a fraction
#: of the motor's, so that it comes to rest exactly like the motor.
LOAD_FRICTION_MIN_FRACTION = 1.0

# ---------------------------------------------------------------- alarms
#: 7.3 / NOTES: |Pset - Pmotor| > 8192 (1/16384 rev) = 180 deg trips at once ...
LOST_PHASE_FAST_COUNTS = U.LOST_PHASE_UNITS * U.COUNTS_PER_REV / U.ONRANGE_UNITS_PER_REV
#: ... and >= 90 deg for about 2 s (4.1).
LOST_PHASE_SLOW_COUNTS = LOST_PHASE_FAST_COUNTS / 2
LOST_PHASE_SLOW_S = 2.0
#: Over current (6.1: "cannot move to its command position and there is a backlog of
#: current"): current at the peak limit, shaft stalled (< 1 rpm), for 1 s. A stall 90 deg or
#: more out of position is classified as lost phase instead (4.1), so the two stay distinct.
OVER_CURRENT_S = 1.0
OVER_CURRENT_STALL_CPS = U.rpm_to_counts_per_s(1.0)
#: Over power / overheat: first-order I^2 t model of the motor and power stage.
THERMAL_TAU_S = 20.0
#: Trips when the filtered I^2 exceeds (1.5 x rated current)^2: peak current (3x rated) trips
#: after ~5.6 s, 2x rated after ~16.5 s, rated current never.
THERMAL_TRIP_FACTOR = 1.5
#: Bus voltage at power-on (rated 60 V DC, manual 1.1).
DEFAULT_BUS_VOLTAGE = 60.0
#: Minimum operating input (2.5: "minimum operation input of +24VDC"): below it the drive
#: is off (VirtualDrive.supply_dip).
MIN_INPUT_V = 24.0
#: Power stage temperature read from the I^2 t state: ambient at 0, the overheat trip at 1
#: (decision: the manuals give no temperatures; 0-55 degC is the operating range, 1.1).
AMBIENT_C = 25.0
OVERHEAT_C = 85.0

# ---------------------------------------------------------------- voltage (back-EMF) limit
#: The bus voltage the motor figures below are given at (rated 60 V DC, manual 1.1).
RATED_BUS_VOLTAGE = 60.0
#: No-load speed at the rated bus = this x the model's maximum speed (DYN2: 5,000 rpm, the
#: speed control range of 1.1) -> 5,500 rpm: the whole range is reachable with torque to
#: spare; +10 V in speed mode (6,000 rpm, 4.2) saturates near 5,480 rpm at 60 V and is
#: reached from about 66 V up (75 V is the permissible maximum, 1.1).
NO_LOAD_SPEED_FACTOR = 1.1
#: Peak torque is available up to this fraction of the no-load speed (3,300 rpm at 60 V),
#: then falls linearly to zero at the no-load speed (motoring only; braking is not limited).
FULL_TORQUE_SPEED_FRACTION = 0.6
#: Below this the bus is treated as this (a drive at 0 V is off; the limit stays defined).
MIN_MODELLED_BUS_V = 1.0
#: Path handover (DTPU for lines and arcs, engine.go_path): the peak of |q''| for
#: q(x) = x - 6x^3 + 8x^4 - 3x^5, at x = (192 - sqrt(10944)) / 360.
_X_PEAK = (192.0 - 10944.0 ** 0.5) / 360.0
HANDOVER_Q2_PEAK = abs(-36.0 * _X_PEAK + 96.0 * _X_PEAK**2 - 60.0 * _X_PEAK**3)

# ---------------------------------------------------------------- settling (quiescent path)
#: A drive whose position error is 0 counts, whose shafts are held by friction and whose
#: torque changes by less than this is at an exact equilibrium: stepping it changes nothing,
#: so time is skipped in O(1).
SETTLED_TORQUE_NM = 1e-7

# ---------------------------------------------------------------- signals
#: JP3-2 analog input: +-10 V reference, +-12 V maximum input (1.1, 2.3); the drive clamps.
ANALOG_INPUT_MAX_V = 12.0
#: Pulse inputs: maximum input frequency (1.1, 4.1). The control channel refuses faster trains.
PULSE_RATE_MAX_HZ = 500_000.0
#: ZRI output is LOW while the shaft is within this many counts of the zero index.
ZRI_HALF_WIDTH_COUNTS = 64
#: JP3 pin 2 (status b6) reads high above this analog level (TTL threshold; decision).
JP3_PIN2_HIGH_V = 2.5
#: Set_Param_Group2 (DYN CAN): Max Speed / Max Accel go to EEPROM for this many writes after
#: power-on, then to RAM only.
GROUP2_EEPROM_WRITES = 10
