"""The servo engine: reference generator, cascaded servo loop, motor + load physics, alarms.

One instance per virtual drive. ``run(n)`` advances ``n`` fixed control periods; the hot
loops keep all state in local variables and allocate nothing, which is what lets 16 drives
run in real time in pure Python. Everything is in encoder counts (65,536 per rev), seconds
and newton-metres.

Per control period, in position servo mode (docs/tuning.md has the model and its numbers):

1. mechanics over the last period under the torque then applied: one inertia, or two masses
   coupled by a spring and a damper (a compliant load); Coulomb friction that holds a shaft
   at rest and stops a sliding one dead, viscous friction, a load torque on the load side
   (semi-implicit Euler), or a blocked shaft;
2. feedback: the encoder (the shaft in the family's counts) and the speed from counts per
   period;
3. reference: S-curve generator (an online trapezoid: accelerate/cruise at Max Accel/Max
   Speed, brake at the last moment so it lands exactly; a new target simply replaces the old
   one, which is DTPU) -> moving-average smoothing -> optional path mapping (line/arc), or a
   wave, or external pulses/analog; a new path during motion hands the reference's speed
   over (see :meth:`go_path`);
4. loops: position P (Main Gain) with velocity feed-forward, plus an acceleration
   feed-forward through the drive's inertia estimate (Adaptive Tuning) -> speed loop PI
   (Speed Gain, Integration Gain) -> torque clamp (peak current x Kt, torque limit; above
   the corner speed the motoring torque falls with the back-EMF to zero at the no-load
   speed, which scales with the bus voltage; the integrator frozen while clamped) -> a
   transport delay of 2 periods -> torque filter a/(s+a), a = 26 x TrqCons -> a 1.5 kHz
   current loop;
5. alarms: lost phase (> 180 deg at once, >= 90 deg for 2 s), over current (peak current
   while stalled for 1 s), I^2 t over power.

A drive at rest with nothing to do reaches an exact equilibrium; ``settled`` then lets time
pass in O(1) until any input changes (every mutator calls :meth:`wake`).

The ideal plant (:meth:`set_ideal`, ``servobus sim ... --plant ideal``) leaves out steps 1,
4 and 5 in position servo: the shaft is wherever the reference is, at the reference's speed,
with no current, and no alarm can trip. A reference at a constant speed (a ``run_speed``
cruising, its smoothing filter full) then advances in O(1) per call as a drive at rest does,
so a drive that turns costs no more than one that stands (docs/virtual-drive.md "The ideal
plant").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from enum import IntEnum

from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode
from servobus.sim.core import constants as K

TWO_PI = 2.0 * math.pi
RAD_PER_COUNT = TWO_PI / U.COUNTS_PER_REV


def friction_step(w: float, net: float, fc: float, fb: float, inv_j: float, h: float) -> float:
    """One mass's speed after a period under ``net`` N m: Coulomb friction ``fc`` holds it
    at rest up to fc and stops a sliding mass dead rather than reversing it; ``fb`` is the
    viscous friction per counts/s (0 on the load side), ``inv_j`` counts/s^2 per N m.

    The one copy every hot loop calls (rigid shaft, and motor and load of the two masses):
    a call costs less than the copies cost to keep in step. The arithmetic's order is the
    traces' (bit-identical runs, tests/sim/test_tuning.py)."""
    if w == 0.0:
        if net > fc:
            return (net - fc) * inv_j * h
        if net < -fc:
            return (net + fc) * inv_j * h
        return w
    wn = w + (net - (fc if w > 0.0 else -fc) - fb * w) * inv_j * h
    return wn if (wn > 0.0) == (w > 0.0) else 0.0


class Servo(IntEnum):
    FREE = 0
    POSITION = 1
    SPEED = 2
    TORQUE = 3


class Ref(IntEnum):
    """Source of the position reference."""

    HOLD = 0
    GEN = 1  # S-curve generator (PTP, constant speed, interpolation path)
    SINE = 2
    SQUARE = 3
    EXT = 4  # pulse train / analog position input


class Gen(IntEnum):
    IDLE = 0
    POS = 1  # go to target
    VEL = 2  # run at a speed (ramped)


PathMap = Callable[[float], float]


class ServoEngine:
    def __init__(self, model: U.MotorModel) -> None:
        self.model = model
        self.h = K.CONTROL_DT
        # physical world (survives power cycles)
        self.p = 0.0  # shaft position, counts
        self.w = 0.0  # shaft speed, counts/s
        self.load_inertia = 0.0  # kg m^2, reflected to the motor
        self.load_friction = 0.0  # N m, Coulomb
        self.disturbance = 0.0  # N m, positive pushes towards +counts (CW)
        #: Compliant coupling (two-mass): resonance (Hz, 0 = rigid) and damping ratio.
        self.resonance_hz = 0.0
        self.damping = K.DEFAULT_DAMPING
        self.load_torque = 0.0  # N m on the load side, against + (a weight being lifted)
        self.pl = 0.0  # load side position and speed (equal to the motor's when rigid)
        self.wl = 0.0
        #: Engine counts per encoder count of the family (DMM 1, YZ-AIM 2).
        self.encoder_q = 1.0
        #: Velocity feed-forward into the speed loop (1: DMM; 0: YZ-AIM, a plain P loop)
        #: and acceleration feed-forward through the adaptive inertia estimate (on/off).
        self.velocity_ff = 1.0
        self.accel_ff = True
        self.j_hat = model.rotor_inertia_kgm2  # the drive's inertia estimate (Adaptive Tuning)
        self.blocked = False
        #: The ideal plant (set_ideal): no mechanics, loop or alarms in position servo.
        self.ideal = False
        self.bus_voltage = K.DEFAULT_BUS_VOLTAGE
        self.heat = 0.0  # filtered I^2, A^2 (thermal state persists like a warm motor)
        self.steps = 0
        self.bl_n = 0  # path handover: its duration in control periods at full pace
        self.bl_x = 1.0  # ... how far it has run (0 -> 1; 1 = none running)
        self.bl_amp = 0.0  # handover amplitude, counts (speed x duration)
        self.bl_base = 0.0  # the path's own reference of the last period, counts
        self.bl_vlim = math.inf  # the axis speed limit the handover keeps to, counts/s
        #: Torque servo speed limit, counts/s (inf: none). The speed loop runs against it and
        #: clamps the torque command, as a drive's torque mode with a speed limit does: the
        #: motor reaches the limit and holds it (DYN5 instance 0x27, "will not exceed").
        self.torque_speed_limit = math.inf
        self.lim_fwd = True  # direction the limit was last held in (its integrator's sign)
        self.set_protections(True)
        self.power_on()
        self.set_gains(40, 40, 20, 127, 127)
        self.set_profile(1.0, 1.0)

    # ------------------------------------------------------------------ state
    def power_on(self) -> None:
        self.servo = Servo.POSITION
        self.ref = self.p
        self.ref_prev = self.p
        self.integ = 0.0  # speed loop integrator, N m
        self.vff = 0.0  # reference speed of the last period (feed-forward), counts/s
        self.tq = 0.0  # actual torque (after delay, torque filter and current loop), N m
        self.tq_cmd = 0.0
        self.tq_filt = 0.0  # torque filter output (current loop reference), N m
        self.tq_d1 = self.tq_d2 = 0.0  # transport delay line, N m
        self.enc_prev = self.encoder_counts()  # encoder reading of the last period
        self.w_est = 0.0  # speed from counts per period, counts/s
        self.j_hat = self.model.rotor_inertia_kgm2  # Adaptive Tuning starts afresh
        self.ref_mode = Ref.HOLD
        self.gen = Gen.IDLE
        self.gp = self.p  # generator coordinate (counts, or path units with a path)
        self.gv = 0.0
        self.gT = self.p
        self.gvc = 0.0
        self.sref = self.p  # smoothed generator coordinate
        self.n_smooth = 1
        self.buf: list[float] = [0.0]
        self.bidx = 0
        self.dsum = 0.0
        self.idle_steps = 0
        self.path: PathMap | None = None
        self.busy = False  # b5: S-curve / line / arc running
        self.wave_center = 0.0
        self.wave_amp = 0.0
        self.wave_phase = 0.0
        self.wave_step = 0.0  # rad per control period
        self.ext_step = 0.0
        self.ext_left = 0
        self.speed_target = 0.0  # counts/s (speed servo) or A (torque servo), before soft start
        self.speed_ref = 0.0
        self.lp_t = 0.0
        self.oc_t = 0.0
        self.trip_code = AlarmCode.NONE
        self.settled = False

    def wake(self) -> None:
        self.settled = False

    def set_ideal(self, ideal: bool) -> None:
        """The ideal plant on or off (see the module docstring): the shaft stops where it
        is, with no torque."""
        self.ideal = bool(ideal)
        self._clear_torque()
        self.w = self.wl = self.w_est = 0.0
        self.pl = self.p
        self.wake()

    def encoder_counts(self) -> float:
        """The encoder's reading in engine counts: the shaft quantised to the family's counts."""
        q = self.encoder_q
        return (self.p / q // 1.0) * q

    def _clear_torque(self) -> None:
        self.tq = self.tq_cmd = self.tq_filt = self.tq_d1 = self.tq_d2 = 0.0

    # ------------------------------------------------------------------ coefficients
    def set_gains(self, main: int, speed: int, integ: int, trq: int, torque_limit: int) -> None:
        """DMM gains (1..127 each, docs/tuning.md): Main Gain -> position P, Speed Gain ->
        speed loop bandwidth on the bare rotor, Integration Gain -> integrator zero, TrqCons ->
        torque filter a = 26 x TrqCons, torque limit in 1/127 of peak."""
        self.gains = (main, speed, integ, trq, torque_limit)
        self.set_loop(K.KP_PER_MAIN_GAIN * main, K.SPEED_BW_PER_SPEED_GAIN * speed,
                      K.KI_PER_INT_GAIN * integ, K.TORQUE_FILTER_PER_UNIT * trq,
                      min(1.0, torque_limit / 127))

    def set_loop(self, kp: float, speed_bw: float, integ_zero: float, filter_a: float,
                 torque_fraction: float) -> None:
        """Loop coefficients: position gain (1/s), speed loop bandwidth on the bare rotor
        (rad/s; 0 = no speed loop), integrator zero (rad/s; 0 = no integral action), torque
        filter pole (rad/s) and the torque limit as a fraction of peak."""
        m = self.model
        self.loop = (kp, speed_bw, integ_zero, filter_a, torque_fraction)
        self._apply_mechanics()
        self.kp = max(0.0, kp)
        # N m per counts/s: rotor inertia x bandwidth (rad/s) x rad/count
        self.kv = m.rotor_inertia_kgm2 * max(0.0, speed_bw) * RAD_PER_COUNT
        self.ki_h = max(0.0, integ_zero) * self.h
        self.alpha = 1.0 - math.exp(-max(filter_a, 1e-9) * self.h)
        self.alpha_c = 1.0 - math.exp(-TWO_PI * K.CURRENT_LOOP_HZ * self.h)
        self.tmax = m.peak_current_a * m.torque_constant_nm_a * max(0.0, min(1.0,
                                                                             torque_fraction))
        self.inv_kt = 1.0 / m.torque_constant_nm_a
        self._apply_voltage_limit()
        self.heat_beta = self.h / K.THERMAL_TAU_S
        self.heat_trip = (self.thermal_trip_factor * m.rated_current_a) ** 2
        self.wake()

    def _apply_mechanics(self) -> None:
        """Plant coefficients from the motor model and the load (docs/tuning.md)."""
        m = self.model
        jm, jl = m.rotor_inertia_kgm2, self.load_inertia
        f = min(max(self.resonance_hz, 0.0), K.RESONANCE_MAX_HZ)
        self.rigid = f <= 0.0 or jl <= 0.0
        self.inv_j = 1.0 / ((jm + jl) * RAD_PER_COUNT)  # counts/s^2 per N m, rigid
        self.inv_jm = 1.0 / (jm * RAD_PER_COUNT)
        self.inv_jl = 1.0 / (max(jl, 1e-12) * RAD_PER_COUNT)
        j_eq = jm * jl / (jm + jl) if jl > 0.0 else 0.0
        omega = TWO_PI * f
        self.kc = omega * omega * j_eq * RAD_PER_COUNT  # N m per count of twist
        self.cc = 2.0 * max(self.damping, 0.0) * omega * j_eq * RAD_PER_COUNT  # per count/s
        self.fc_m = m.friction_nm
        self.fc_l = self.load_friction + K.LOAD_FRICTION_MIN_FRACTION * m.friction_nm
        self.fc = m.friction_nm + self.load_friction
        self.fb = m.friction_nm * K.VISCOUS_PER_1000RPM / U.rpm_to_counts_per_s(1000.0)
        self.j_max = jm * K.ADAPT_MAX_RATIO
        self.j_true = jm + jl
        self.j_hat = min(max(self.j_hat, jm), self.j_max)
        if self.rigid:
            self.pl, self.wl = self.p, self.w

    def _apply_voltage_limit(self) -> None:
        """Back-EMF: full torque up to the corner speed, then linearly less motoring torque
        down to none at the no-load speed; both scale with the bus voltage (2.5: "voltage /
        speed gradient of the servo motor"). Braking torque is not limited."""
        m = self.model
        volts = max(self.bus_voltage, K.MIN_MODELLED_BUS_V)
        w_nl = (U.rpm_to_counts_per_s(m.max_speed_rpm * K.NO_LOAD_SPEED_FACTOR)
                * volts / K.RATED_BUS_VOLTAGE)
        self.w_corner = w_nl * K.FULL_TORQUE_SPEED_FRACTION
        self.w_noload = w_nl
        self.tv_slope = m.peak_current_a * m.torque_constant_nm_a / (w_nl - self.w_corner)

    def set_bus_voltage(self, volts: float) -> None:
        self.bus_voltage = float(volts)
        self._apply_voltage_limit()
        self.wake()

    def set_protections(self, enabled: bool) -> None:
        """The DMM alarms (lost phase, over current, I^2 t over power) on or off.

        On for the DMM drive (servobus.sim.dmm.drive); off in the protocol-free
        :class:`servobus.sim.core.motor.Motor`, under a family that models its own (YZ-AIM:
        stall and current limit, docs/yzaim.md). Off, the thresholds are infinite, so the
        hot loops stay unchanged."""
        inf = math.inf
        self.lp_fast = K.LOST_PHASE_FAST_COUNTS if enabled else inf
        self.lp_slow = K.LOST_PHASE_SLOW_COUNTS if enabled else inf
        self.lp_slow_s = K.LOST_PHASE_SLOW_S if enabled else inf
        self.oc_trip_s = K.OVER_CURRENT_S if enabled else inf
        self.thermal_trip_factor = K.THERMAL_TRIP_FACTOR if enabled else inf
        if hasattr(self, "loop"):
            self.set_loop(*self.loop)

    def set_profile(self, vmax: float, amax: float) -> None:
        """Generator limits in generator units per s and per s^2."""
        self.vmax = max(vmax, 1e-9)
        self.amax = max(amax, 1e-9)
        self.ah = self.amax * self.h
        self.inv_ah2x2 = 2.0 / (self.ah * self.h)
        self.wake()

    def set_soft_start(self, rise_s: float) -> None:
        """Speed/torque servo soft start: first-order filter with 10-90 % rise ``rise_s``."""
        tau = rise_s / math.log(9.0)
        self.ss_alpha = 1.0 - math.exp(-self.h / tau)
        self.wake()

    # ------------------------------------------------------------------ commands
    def hold_here(self) -> None:
        """Servo (re)starts: reference = shaft, errors and generator cleared."""
        self.ref = self.ref_prev = self.p
        self.integ = 0.0
        self.tq_cmd = self.tq_d1 = self.tq_d2 = 0.0
        self.tq_filt = self.tq
        self.vff = 0.0
        self.enc_prev = self.encoder_counts()
        self.w_est = 0.0
        self._reset_gen(self.p, 0.0)
        self.ref_mode = Ref.HOLD
        self.busy = False
        self.ext_left = 0
        self.lp_t = self.oc_t = 0.0
        self.wake()

    def freeze_reference(self) -> None:
        """Emergency stop: the reference stops where it is (motion left is dropped); the
        motor runs out its following error and brakes at the torque limit."""
        self._reset_gen(self.ref, 0.0)
        self.ref_prev = self.ref
        self.ref_mode = Ref.HOLD
        self.busy = False
        self.ext_left = 0
        self.wake()

    def _reset_gen(self, coord: float, speed: float) -> None:
        """Generator at ``coord`` moving at ``speed``, as if it had been for a filter window
        (so the smoothed reference speed is continuous)."""
        n = self.n_smooth
        d = speed * self.h
        self.sref = coord
        self.gp = self.gT = coord + d * (n - 1) / 2
        self.gv = speed
        self.gen = Gen.IDLE
        for i in range(n):
            self.buf[i] = d
        self.dsum = d * n
        self.idle_steps = 0
        self.path = None
        self.bl_n = 0
        self.bl_x = 1.0

    def _gen_speed_now(self) -> float:
        """Reference speed (counts/s) the next generator motion continues from."""
        if self.ref_mode == Ref.GEN:
            if self.path is None:
                return self.dsum / (self.n_smooth * self.h)
            return self.vff  # a path: the axis reference's own speed (DTPU out of a path)
        if self.ref_mode == Ref.SINE:
            return self.wave_amp * self.wave_step / self.h * math.cos(self.wave_phase)
        return 0.0

    def _enter_gen(self, smoothing_s: float) -> None:
        """Continue from the running S-curve (DTPU) or start one from the reference."""
        if self.ref_mode == Ref.GEN and self.path is None:
            return  # DTPU: same generator state, speed continuous
        speed = self._gen_speed_now()
        n = max(1, round(smoothing_s / self.h))
        if n != self.n_smooth:
            self.n_smooth = n
            self.buf = [0.0] * n
            self.bidx = 0
        self._reset_gen(self.ref, speed)
        self.ref_mode = Ref.GEN

    def go_to(self, target: float, smoothing_s: float) -> None:
        self._enter_gen(smoothing_s)
        self.gT = target
        self.gen = Gen.POS
        self.busy = True
        self.idle_steps = 0
        self.wake()

    def run_speed(self, speed: float, smoothing_s: float) -> None:
        self._enter_gen(smoothing_s)
        self.gvc = speed
        self.gen = Gen.VEL
        self.busy = False
        self.idle_steps = 0
        self.wake()

    @property
    def path_speed(self) -> float:
        """Speed of the running path coordinate (path counts/s; 0 without a path)."""
        if self.ref_mode != Ref.GEN or self.path is None:
            return 0.0
        return self.dsum / (self.n_smooth * self.h)

    def go_path(self, length: float, path: PathMap, smoothing_s: float, *,
                start_speed: float = 0.0, handover: float = 0.0,
                speed_limit: float = math.inf) -> None:
        """Run the generator 0 -> ``length`` along ``path`` (maps coordinate -> counts),
        starting at ``start_speed`` (path counts/s).

        DTPU for paths (7.5): ``handover`` is the axis reference speed (counts/s) the path
        does not take over. It is added as h(t) = v0 T q(t/T), q(x) = x - 6x^3 + 8x^4 - 3x^5:
        speed v0 and no acceleration at the start, none of position, speed or acceleration
        at the end, so the reference keeps its speed, the path's end point is exact and the
        acceleration stays continuous. max |q''| = 3.94, hence T = 3.94 v0 / Max Accel keeps
        the handover's own acceleration within Max Accel (constants.HANDOVER_Q2_PEAK).

        ``speed_limit`` (counts/s, the axis' Max Speed): the path speeds up while the handed
        over speed decays, and their sum would exceed Max Speed (a line at feed 127 taking
        over a point-to-point move at Max Speed: +27 %). The handover's clock is slowed
        whenever path speed + handover speed would pass +-speed_limit, so the sum holds the
        limit instead; h(t) keeps its shape (it only runs slower), so it still ends at 0 and
        the path's end point stays exact. The path waits for the handover to finish."""
        n = max(1, round(smoothing_s / self.h))
        if n != self.n_smooth:
            self.n_smooth = n
            self.buf = [0.0] * n
        self.bidx = 0
        self._reset_gen(0.0, start_speed)
        if handover:
            steps = max(1, math.ceil(K.HANDOVER_Q2_PEAK * abs(handover) / self.amax / self.h))
            self.bl_n, self.bl_x, self.bl_amp = steps, 0.0, handover * steps * self.h
            self.bl_base = path(0.0)
            self.bl_vlim = speed_limit
        self.path = path
        self.gT = length
        self.gen = Gen.POS
        self.ref_mode = Ref.GEN
        self.busy = True
        self.wake()

    def start_wave(self, square: bool, amp: float, hz: float, center: float | None) -> None:
        if self.ref_mode not in (Ref.SINE, Ref.SQUARE) or center is not None:
            self.wave_center = self.ref if center is None else center
            self.wave_phase = 0.0
        self.ref_mode = Ref.SQUARE if square else Ref.SINE
        self.wave_amp = amp
        self.wave_step = TWO_PI * hz * self.h
        self.busy = False
        self.wake()

    def stop_wave(self, smoothing_s: float) -> None:
        """Wave off: brake with the generator back to the wave centre, speed continuous."""
        if self.ref_mode not in (Ref.SINE, Ref.SQUARE):
            return
        center = self.wave_center
        if self.ref_mode == Ref.SQUARE:
            self.ref_mode = Ref.HOLD
        self._enter_gen(smoothing_s)
        self.gT = center
        self.gen = Gen.POS
        self.wake()

    def ext_move(self, counts: float, seconds: float) -> None:
        """Pulse-train input: ``counts`` spread evenly over ``seconds`` (0 = at once)."""
        if self.ref_mode != Ref.EXT:
            self._reset_gen(self.ref, 0.0)
            self.ref_mode = Ref.EXT
            self.busy = False
        steps = max(1, round(seconds / self.h))
        if steps == 1:
            self.ref += counts
            self.ref_prev = self.ref
            self.ext_left = 0
        else:
            pending = self.ext_step * self.ext_left
            self.ext_left = steps
            self.ext_step = (counts + pending) / steps
        self.wake()

    def ext_set(self, position: float) -> None:
        """Analog position input: the reference jumps to ``position``."""
        self._reset_gen(self.ref, 0.0)
        self.ref_mode = Ref.EXT
        self.ext_left = 0
        self.busy = False
        self.ref = self.ref_prev = position
        self.wake()

    @property
    def ref_moving(self) -> bool:
        m = self.ref_mode
        if m == Ref.GEN:
            return True
        if m == Ref.EXT:
            return self.ext_left > 0
        return m != Ref.HOLD and self.wave_step != 0.0

    # ------------------------------------------------------------------ readouts
    @property
    def current_a(self) -> float:
        return self.tq * self.inv_kt if self.servo != Servo.FREE else 0.0

    # ------------------------------------------------------------------ time
    def run(self, n: int) -> int:
        """Advance ``n`` control periods; returns how many ran before an alarm tripped."""
        if n <= 0:
            return 0
        if self.settled:
            self._skip(n)
            return n
        s = self.servo
        if s == Servo.POSITION:
            if self.ideal and self._cruise(n):
                return n
            done = self._run_position(n)
        elif s == Servo.FREE:
            done = self._run_free(n)
        else:
            done = self._run_speed_torque(n)
        self.steps += done
        return done

    def _skip(self, n: int) -> None:
        """Settled: only the thermal state moves (closed form, cannot cross the trip level)."""
        i2 = self.current_a ** 2
        self.heat = i2 + (self.heat - i2) * math.exp(-n * self.heat_beta)
        self.steps += n

    def _cruise(self, n: int) -> bool:
        """Ideal plant, the generator cruising at a constant speed with no path and its
        smoothing filter full of that speed: ``n`` periods at once, as the loop would run them
        (up to rounding); False, with nothing changed, in any other state."""
        if (self.ref_mode != Ref.GEN or self.gen != Gen.VEL or self.gv != self.gvc
                or self.path is not None or self.bl_x < 1.0):
            return False
        d = self.gv * self.h
        if any(b != d for b in self.buf):
            return False
        step = self.dsum / self.n_smooth
        self.gp += n * d
        self.sref += n * step
        self.ref = self.p = self.pl = self.sref
        self.ref_prev = self.ref - step
        self.w = self.wl = self.vff = step / self.h
        self.w_est = self.w
        self.enc_prev = self.encoder_counts()
        self.bidx = (self.bidx + n) % self.n_smooth
        self.idle_steps = 0
        self.heat *= math.exp(-n * self.heat_beta)
        self.steps += n
        return True

    def _settle_check(self) -> bool:
        return (self.current_a ** 2 < self.heat_trip and self.lp_t == 0.0
                and self.oc_t == 0.0)

    def _trip(self, code: AlarmCode) -> None:
        self.trip_code = code
        self.servo = Servo.FREE
        self._clear_torque()
        self.integ = 0.0
        self.busy = False
        self.ref_mode = Ref.HOLD
        self.gen = Gen.IDLE
        self.ext_left = 0

    # The hot loop. Kept deliberately flat: locals only, no calls except sqrt/sin and the
    # optional path map, no allocation.
    def _run_position(self, n: int) -> int:
        h = self.h
        inv_h = 1.0 / h
        sqrt = math.sqrt
        sin = math.sin
        p, w, ref = self.p, self.w, self.ref
        integ, tq, tq_c, heat = self.integ, self.tq, self.tq_cmd, self.heat
        tf, d1, d2, alpha_c = self.tq_filt, self.tq_d1, self.tq_d2, self.alpha_c
        kp, kv, ki_h, alpha = self.kp, self.kv, self.ki_h, self.alpha
        vff, ffv = self.vff, self.velocity_ff
        q = self.encoder_q
        inv_q = 1.0 / q
        enc_prev, w_est = self.enc_prev, self.w_est
        # acceleration feed-forward: the inertia estimate (kg m^2) -> N m per counts/s^2
        jh, j_goal = self.j_hat, min(self.j_true, self.j_max)
        adapt = h / K.ADAPT_TAU_S if self.accel_ff else 0.0
        kaff = jh * RAD_PER_COUNT if self.accel_ff else 0.0
        tmax, inv_kt = self.tmax, self.inv_kt
        w_corner, w_noload, tv_slope = self.w_corner, self.w_noload, self.tv_slope
        fc, fb, inv_j, rigid = self.fc, self.fb, self.inv_j, self.rigid
        fc_m, fc_l, inv_jm, inv_jl = self.fc_m, self.fc_l, self.inv_jm, self.inv_jl
        kc, cc, pl, wl = self.kc, self.cc, self.pl, self.wl
        dist, blocked = self.disturbance - self.load_torque, self.blocked
        beta, heat_trip = self.heat_beta, self.heat_trip
        lp_fast, lp_slow, lp_slow_s = self.lp_fast, self.lp_slow, self.lp_slow_s
        oc_trip_s = self.oc_trip_s
        lp_t, oc_t = self.lp_t, self.oc_t
        oc_stall = K.OVER_CURRENT_STALL_CPS
        mode = int(self.ref_mode)
        gen = int(self.gen)
        gp, gv, g_t, gvc = self.gp, self.gv, self.gT, self.gvc
        sref, dsum, buf, bidx, nsm = self.sref, self.dsum, self.buf, self.bidx, self.n_smooth
        inv_n = 1.0 / nsm
        idle = self.idle_steps
        path = self.path
        bl_x, bl_amp, bl_base, bl_vlim = self.bl_x, self.bl_amp, self.bl_base, self.bl_vlim
        inv_bl_n = 1.0 / self.bl_n if self.bl_n else 0.0
        vmax, ah, inv_ah2x2 = self.vmax, self.ah, self.inv_ah2x2
        arrive = ah * h
        w_amp, w_phase, w_step, w_center = (self.wave_amp, self.wave_phase, self.wave_step,
                                            self.wave_center)
        ext_step, ext_left = self.ext_step, self.ext_left
        busy = self.busy
        ideal = self.ideal
        trip = AlarmCode.NONE
        eps_t = K.SETTLED_TORQUE_NM
        settled = False
        k = 0
        tc = tq_c
        while k < n:
            k += 1
            # ---- mechanics over the last period, under the torque then applied
            if ideal:
                pass  # the ideal plant: the shaft follows the reference (after it, below)
            elif blocked:
                w = wl = 0.0
            elif rigid:
                w = friction_step(w, tq + dist, fc, fb, inv_j, h)
                p += w * h
            else:  # two-mass: motor -- spring kc, damper cc -- load
                tw = kc * (p - pl) + cc * (w - wl)
                w = friction_step(w, tq - tw, fc_m, fb, inv_jm, h)
                wl = friction_step(wl, tw + dist, fc_l, 0.0, inv_jl, h)  # no viscous term
                p += w * h
                pl += wl * h
            # ---- feedback: the encoder now, speed from counts per period
            enc = (p * inv_q // 1.0) * q
            w_est = (enc - enc_prev) * inv_h
            enc_prev = enc
            ref_prev = ref
            # ---- reference
            if mode == 1:  # GEN
                if gen == 1:
                    e = g_t - gp
                    ae = e if e >= 0.0 else -e
                    if ae <= arrive and -2 * ah <= gv <= 2 * ah:
                        d = e
                        gv = 0.0
                        gen = 0
                    else:
                        vs = ah * (sqrt(0.25 + ae * inv_ah2x2) - 0.5)
                        if vs > vmax:
                            vs = vmax
                        if e < 0.0:
                            vs = -vs
                        dv = vs - gv
                        if dv > ah:
                            dv = ah
                        elif dv < -ah:
                            dv = -ah
                        gv += dv
                        d = gv * h
                elif gen == 2:
                    dv = gvc - gv
                    if dv > ah:
                        dv = ah
                    elif dv < -ah:
                        dv = -ah
                    gv += dv
                    d = gv * h
                    if gv == 0.0 and gvc == 0.0:
                        gen = 0
                else:
                    d = 0.0
                gp += d
                old = buf[bidx]
                buf[bidx] = d
                bidx += 1
                if bidx == nsm:
                    bidx = 0
                dsum += d - old
                sref += dsum * inv_n
                if gen == 0:
                    idle += 1
                    if idle >= nsm and bl_x >= 1.0:  # filter flushed: land exactly
                        sref = gp
                        dsum = 0.0
                        mode = 0
                        busy = False
                        g_t = gp
                else:
                    idle = 0
                ref = sref if path is None else path(sref)
                if bl_x < 1.0:  # path handover (go_path), paced to keep the speed limit
                    vp = (ref - bl_base) * inv_h
                    bl_base = ref
                    x = bl_x
                    q0 = x * (1.0 - x * x * (6.0 - x * (8.0 - 3.0 * x)))
                    x += inv_bl_n
                    if x > 1.0:
                        x = 1.0
                    vh = bl_amp * (x * (1.0 - x * x * (6.0 - x * (8.0 - 3.0 * x))) - q0) * inv_h
                    if vp + vh > bl_vlim and vh > 0.0:
                        r = (bl_vlim - vp) / vh
                        x = bl_x + (r if r > 0.0 else 0.0) * inv_bl_n
                    elif vp + vh < -bl_vlim and vh < 0.0:
                        r = (-bl_vlim - vp) / vh
                        x = bl_x + (r if r > 0.0 else 0.0) * inv_bl_n
                    bl_x = x
                    ref += bl_amp * x * (1.0 - x * x * (6.0 - x * (8.0 - 3.0 * x)))
            elif mode == 2:  # SINE
                w_phase += w_step
                if w_phase >= TWO_PI:
                    w_phase -= TWO_PI
                ref = w_center + w_amp * sin(w_phase)
            elif mode == 3:  # SQUARE
                w_phase += w_step
                if w_phase >= TWO_PI:
                    w_phase -= TWO_PI
                ref = w_center + (w_amp if w_phase < math.pi else -w_amp)
                ref_prev = ref  # a step command: no feed-forward
            elif mode == 4 and ext_left > 0:  # EXT pulses
                ref += ext_step
                ext_left -= 1
            if ideal:  # the shaft is at the reference: no loop, no current, no alarm
                w = vff = (ref - p) * inv_h
                p = ref
                heat -= heat * beta
                if w == 0.0 and (mode == 0 or (mode == 4 and ext_left == 0)):
                    settled = True
                    break
                continue
            # ---- servo loop: position P -> speed PI -> clamp -> delay -> filter -> current
            e = ref - p
            eq = ((e * inv_q + 0.5) // 1.0) * q  # the error in encoder counts
            vff_prev = vff
            vff = (ref - ref_prev) * inv_h
            acc = (vff - vff_prev) * inv_h
            if acc != 0.0 and adapt:  # Adaptive Tuning learns while the reference accelerates
                jh += (j_goal - jh) * adapt
                kaff = jh * RAD_PER_COUNT
            ev = ffv * vff + kp * eq - w_est
            tc = kv * ev + integ + acc * kaff
            hi = tmax
            lo = -tmax
            if w > w_corner:  # back-EMF: less motoring torque at speed
                lim = tv_slope * (w_noload - w)
                if lim < hi:
                    hi = lim if lim > 0.0 else 0.0
            elif w < -w_corner:
                lim = tv_slope * (w_noload + w)
                if lim < hi:
                    lo = -lim if lim > 0.0 else 0.0
            if tc > hi:
                tc = hi
            elif tc < lo:
                tc = lo
            else:
                integ += kv * ki_h * ev  # frozen while clamped (anti-windup)
            td = d2
            d2 = d1
            d1 = tc
            tf += (td - tf) * alpha
            tq += (tf - tq) * alpha_c
            # ---- protection
            i = tq * inv_kt
            heat += (i * i - heat) * beta
            if heat > heat_trip:
                trip = AlarmCode.OVERHEAT
                break
            ae = eq if eq >= 0.0 else -eq  # what the drive sees: encoder counts
            if ae > lp_fast:
                trip = AlarmCode.LOST_PHASE
                break
            if ae >= lp_slow:
                lp_t += h
                if lp_t >= lp_slow_s:
                    trip = AlarmCode.LOST_PHASE
                    break
                oc_t = 0.0
            else:
                lp_t = 0.0
                if (tc == tmax or tc == -tmax) and -oc_stall < w < oc_stall:
                    oc_t += h
                    if oc_t >= oc_trip_s:
                        trip = AlarmCode.OVER_CURRENT
                        break
                else:
                    oc_t = 0.0
                if (mode == 0 or (mode == 4 and ext_left == 0)) and eq == 0.0 \
                        and w == 0.0 and wl == 0.0 and w_est == 0.0 \
                        and -eps_t < tc - tq < eps_t and -eps_t < tc - tf < eps_t \
                        and d1 == tc and d2 == tc:
                    settled = True
                    break
        tq_c = tc
        self.p, self.w, self.ref, self.ref_prev = p, w, ref, ref_prev if k else self.ref_prev
        self.pl, self.wl = (p, w) if rigid or ideal else (pl, wl)
        self.integ, self.tq, self.tq_cmd, self.heat = integ, tq, tq_c, heat
        self.tq_filt, self.tq_d1, self.tq_d2 = tf, d1, d2
        self.enc_prev, self.w_est, self.j_hat = enc_prev, w_est, jh
        self.vff = vff
        self.lp_t, self.oc_t = lp_t, oc_t
        self.ref_mode = Ref(mode)
        self.gen, self.gp, self.gv, self.gT = Gen(gen), gp, gv, g_t
        self.sref, self.dsum, self.bidx, self.idle_steps = sref, dsum, bidx, idle
        self.bl_x, self.bl_base = bl_x, bl_base
        self.wave_phase = w_phase
        self.ext_left = ext_left
        self.busy = busy
        if trip:
            self._trip(trip)
            return k
        if settled and self._settle_check():
            self.settled = True
            self.ref_prev = self.ref
            self._skip(n - k)
            return k  # steps counted by _skip
        return k

    def _run_free(self, n: int) -> int:
        """Servo off: the shaft coasts under friction and the load's torques; no current."""
        h = self.h
        p, w, heat, beta = self.p, self.w, self.heat, self.heat_beta
        fc, fb, inv_j, rigid = self.fc, self.fb, self.inv_j, self.rigid
        fc_m, fc_l, inv_jm, inv_jl = self.fc_m, self.fc_l, self.inv_jm, self.inv_jl
        kc, cc, pl, wl = self.kc, self.cc, self.pl, self.wl
        dist, blocked = self.disturbance - self.load_torque, self.blocked
        tq = 0.0
        k = 0
        while k < n:
            tw = kc * (p - pl)
            if blocked or (w == 0.0 and wl == 0.0 and (
                    (rigid and -fc <= dist <= fc)
                    or (not rigid and -fc_m <= tw <= fc_m and -fc_l <= tw + dist <= fc_l))):
                break  # at rest for good (or blocked): only the heat decays
            k += 1
            if blocked:
                w = wl = 0.0
            elif rigid:
                w = friction_step(w, tq + dist, fc, fb, inv_j, h)
                p += w * h
            else:  # two-mass: motor -- spring kc, damper cc -- load
                tw = kc * (p - pl) + cc * (w - wl)
                w = friction_step(w, tq - tw, fc_m, fb, inv_jm, h)
                wl = friction_step(wl, tw + dist, fc_l, 0.0, inv_jl, h)  # no viscous term
                p += w * h
                pl += wl * h
            heat -= heat * beta
        self.p, self.w, self.heat, self.tq = p, w, heat, 0.0
        self.pl, self.wl = (p, w) if rigid else (pl, wl)
        if blocked:
            self.w = self.wl = 0.0
        self.ref = self.ref_prev = p
        self.enc_prev = self.encoder_counts()
        if k < n:
            self.settled = True
            self._skip(n - k)  # counts its own periods; run() adds the k that ran
        return k

    def _run_speed_torque(self, n: int) -> int:
        """Speed servo (analog speed reference) or torque servo (analog current reference)."""
        h = self.h
        p, w, integ, tq, heat = self.p, self.w, self.integ, self.tq, self.heat
        kv, ki_h, alpha, tmax, inv_kt = self.kv, self.ki_h, self.alpha, self.tmax, self.inv_kt
        w_corner, w_noload, tv_slope = self.w_corner, self.w_noload, self.tv_slope
        fc, fb, inv_j, rigid = self.fc, self.fb, self.inv_j, self.rigid
        fc_m, fc_l, inv_jm, inv_jl = self.fc_m, self.fc_l, self.inv_jm, self.inv_jl
        kc, cc, pl, wl = self.kc, self.cc, self.pl, self.wl
        dist, blocked = self.disturbance - self.load_torque, self.blocked
        beta, heat_trip = self.heat_beta, self.heat_trip
        ss, target, sref = self.ss_alpha, self.speed_target, self.speed_ref
        speed_mode = self.servo == Servo.SPEED
        wlim = self.torque_speed_limit
        limited = not speed_mode and wlim < math.inf
        lim_fwd = self.lim_fwd
        kt = self.model.torque_constant_nm_a
        oc_t, oc_stall, oc_trip_s = self.oc_t, K.OVER_CURRENT_STALL_CPS, self.oc_trip_s
        trip = AlarmCode.NONE
        k = 0
        tc = self.tq_cmd
        while k < n:
            k += 1
            sref += (target - sref) * ss
            hi = tmax
            lo = -tmax
            if w > w_corner:  # back-EMF, as in _run_position
                lim = tv_slope * (w_noload - w)
                if lim < hi:
                    hi = lim if lim > 0.0 else 0.0
            elif w < -w_corner:
                lim = tv_slope * (w_noload + w)
                if lim < hi:
                    lo = -lim if lim > 0.0 else 0.0
            if speed_mode:
                ev = sref - w
                tc = kv * ev + integ
                if tc > hi:
                    tc = hi
                elif tc < lo:
                    tc = lo
                else:
                    integ += kv * ki_h * ev
            else:
                tc = sref * kt
                if limited:  # the speed loop holds |w| <= wlim by clamping the torque
                    forward = sref >= 0.0
                    if forward != lim_fwd:
                        lim_fwd = forward
                        integ = 0.0
                    ev = (wlim if forward else -wlim) - w
                    u = kv * ev + integ
                    if forward:
                        if u < tc:
                            if u > lo:
                                tc = u
                                integ += kv * ki_h * ev
                            else:
                                tc = lo
                    elif u > tc:
                        if u < hi:
                            tc = u
                            integ += kv * ki_h * ev
                        else:
                            tc = hi
                if tc > hi:
                    tc = hi
                elif tc < lo:
                    tc = lo
            tq += (tc - tq) * alpha
            if blocked:
                w = wl = 0.0
            elif rigid:
                w = friction_step(w, tq + dist, fc, fb, inv_j, h)
                p += w * h
            else:  # two-mass: motor -- spring kc, damper cc -- load
                tw = kc * (p - pl) + cc * (w - wl)
                w = friction_step(w, tq - tw, fc_m, fb, inv_jm, h)
                wl = friction_step(wl, tw + dist, fc_l, 0.0, inv_jl, h)  # no viscous term
                p += w * h
                pl += wl * h
            i = tq * inv_kt
            heat += (i * i - heat) * beta
            if heat > heat_trip:
                trip = AlarmCode.OVERHEAT
                break
            if speed_mode and (tc == tmax or tc == -tmax) and -oc_stall < w < oc_stall:
                oc_t += h
                if oc_t >= oc_trip_s:
                    trip = AlarmCode.OVER_CURRENT
                    break
            else:
                oc_t = 0.0
        self.p, self.w, self.integ, self.tq, self.tq_cmd, self.heat = p, w, integ, tq, tc, heat
        self.speed_ref, self.oc_t, self.lim_fwd = sref, oc_t, lim_fwd
        self.pl, self.wl = (p, w) if rigid else (pl, wl)
        self.tq_filt = tq
        self.ref = self.ref_prev = p
        self.enc_prev = self.encoder_counts()
        if trip:
            self._trip(trip)
        return k
