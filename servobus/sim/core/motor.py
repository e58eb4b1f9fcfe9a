"""Motor: the protocol-free servo motor on the engine, with no vendor's parameters or alarms.

A family's virtual drive that keeps its own registers, units and protections sits on it
(the YZ-AIM motor, :mod:`servobus.sim.yzaim.motor`); the DMM drive
(:mod:`servobus.sim.dmm.drive`) drives the engine itself with its parameter table and alarms.
Neither switches the other's features off: this core has none to switch.

Units: counts of the engine (65,536 per revolution, :mod:`servobus.sim.core.constants`),
rpm, amperes; gains and the torque limit on the engine's 1..127 scale; time in simulated
seconds (``advance_to``), one control period (``CONTROL_HZ``) underneath. The servo runs in
position mode when on; every motion command is ignored (False) while it is free.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode
from servobus.sim.core import constants as K
from servobus.sim.core.engine import Ref, Servo, ServoEngine
from servobus.sim.core.loads import LoadSettings

#: Soft start of the engine's speed/torque servo (unused in position mode); the engine's
#: own rise for its factory acceleration, set so that every coefficient is defined.
SOFT_START_S = U.soft_start_rise_s(30)
#: Engine gains at power-on (main, speed, integration, torque filter, torque limit): the
#: engine's scale, a family's front end sets its own with :meth:`Motor.set_gains`.
DEFAULT_GAINS = (40, 40, 20, 127, 127)


class EngineShaft:
    """What every simulated motor shares of its servo engine (the DMM drive and the YZ-AIM
    motor alike): the readouts - position from the origin, following error, periods, speed,
    current - and the world's hold on the shaft (load, disturbance, a blocked shaft).
    A subclass re-applies its parameters in :meth:`_apply_load` after a load change."""

    _engine: ServoEngine
    _origin: float
    #: Called with the shaft after each control period while set (a trace's capture); each
    #: subclass types it with itself.
    period_observer: Any

    def _apply_load(self) -> None:
        raise NotImplementedError

    def _run_periods(self, n: int) -> None:
        """Run ``n`` control periods: all at once, or one by one under the period observer
        (read again every period: it may stop itself). A DMM alarm the engine trips ends
        its run early; :meth:`_tripped` is told and the periods go on."""
        eng = self._engine
        while n > 0:
            before = eng.steps
            observer = self.period_observer
            if observer is None:
                eng.run(n)
            elif eng.run(1):
                observer(self)
            n -= eng.steps - before
            if eng.trip_code is not AlarmCode.NONE:
                self._tripped(eng.trip_code)
            elif eng.steps == before:
                break

    def _switch_servo(self, mode: Servo) -> bool:
        """The engine's servo in ``mode``; a change holds the shaft where it is (no torque
        when free, the speed reference reset). True when it changed."""
        eng = self._engine
        if mode == eng.servo:
            return False
        eng.servo = mode
        eng.hold_here()
        if mode == Servo.FREE:
            eng.tq = eng.tq_cmd = 0.0
        eng.speed_ref = 0.0
        return True

    def _tripped(self, code: AlarmCode) -> None:
        """The engine tripped ``code``: only with its protections on (the DMM drive)."""

    # ---------------------------------------------------------------- world
    def set_load(self, *, inertia: float | None = None, friction: float | None = None) -> None:
        """Load reflected to the motor shaft: inertia (kg m^2), Coulomb friction (N m)."""
        eng = self._engine
        if inertia is not None:
            eng.load_inertia = max(0.0, float(inertia))
        if friction is not None:
            eng.load_friction = max(0.0, float(friction))
        self._apply_load()

    def set_mechanics(self, settings: LoadSettings) -> None:
        """A load of :mod:`servobus.sim.core.loads`: inertia ratio, resonance, damping and
        load torque (each left as it is when None)."""
        eng = self._engine
        if settings.inertia is not None:
            eng.load_inertia = settings.inertia * eng.model.rotor_inertia_kgm2
        if settings.resonance is not None:
            eng.resonance_hz = settings.resonance
        if settings.damping is not None:
            eng.damping = settings.damping
        if settings.load_torque is not None:
            eng.load_torque = settings.load_torque
        self._apply_load()

    def mechanics(self) -> dict[str, float]:
        """The load as :meth:`set_mechanics` sets it, plus the drive's inertia estimate."""
        eng = self._engine
        jm = eng.model.rotor_inertia_kgm2
        return {"inertia": eng.load_inertia / jm, "resonance": eng.resonance_hz,
                "damping": eng.damping, "load_torque": eng.load_torque,
                "inertia_estimate": eng.j_hat / jm - 1.0}

    def set_disturbance(self, torque_nm: float) -> None:
        """External torque on the shaft, positive towards + (CW)."""
        self._engine.disturbance = float(torque_nm)
        self._engine.wake()

    def set_blocked(self, blocked: bool) -> None:
        """Mechanically block the shaft (it stops dead and cannot move)."""
        self._engine.blocked = bool(blocked)
        if blocked:
            self._engine.w = 0.0
        self._engine.wake()

    def set_ideal(self, ideal: bool) -> None:
        """The ideal plant (``--plant ideal``, servobus.sim.core.engine): in position servo
        the shaft follows the reference exactly, with no current and no loop alarms."""
        self._engine.set_ideal(ideal)

    def world(self) -> dict[str, float | bool]:
        """The world around the shaft as set by set_load, set_disturbance and set_blocked
        (the control channel's state readout)."""
        eng = self._engine
        return {"load_inertia_kgm2": eng.load_inertia, "load_friction_nm": eng.load_friction,
                "load_torque_nm": eng.disturbance, "blocked": eng.blocked}

    # ---------------------------------------------------------------- readouts

    @property
    def position(self) -> int:
        return round(self._engine.p - self._origin)

    @property
    def position_error(self) -> float:
        """Commanded reference - actual position, counts (what a drive's trace shows)."""
        return self._engine.ref - self._engine.p

    @property
    def shaft_position(self) -> float:
        """Motor shaft position in counts from the origin, unrounded (traces, step tests)."""
        return self._engine.p - self._origin

    @property
    def load_position(self) -> float:
        """Load side position in motor counts from the origin (the motor's when rigid)."""
        return self._engine.pl - self._origin

    @property
    def periods(self) -> int:
        """Control periods run since creation (period ``k`` ends at ``k / CONTROL_HZ`` s)."""
        return self._engine.steps

    @property
    def speed_rpm(self) -> float:
        return U.counts_per_s_to_rpm(self._engine.w)

    @property
    def current_a(self) -> float:
        """Motor current (torque producing), A; positive = torque towards + (CW)."""
        return self._engine.current_a


class Motor(EngineShaft):
    """One simulated servo motor and its position loop. Not thread-safe."""

    def __init__(self, model: U.MotorModel) -> None:
        self.model = model
        self.time = 0.0
        self._engine = ServoEngine(model)
        self._engine.set_protections(False)  # a family models its own protections
        self._gains = DEFAULT_GAINS
        self._loop: tuple[float, float, float, float, float] | None = None
        self._profile = (1.0, 1.0)  # generator speed (rpm), acceleration (rpm/s)
        self._free = False
        #: Called after every control period when set (servobus.sim.core.capture).
        self.period_observer: Callable[[Motor], None] | None = None
        eng = self._engine
        eng.power_on()
        eng.servo = Servo.FREE
        self._apply()
        self._origin = eng.p
        self._apply_servo()

    # ---------------------------------------------------------------- settings
    def _apply_load(self) -> None:
        self._apply()

    def _apply(self) -> None:
        eng = self._engine
        if self._loop is None:
            eng.set_gains(*self._gains)
        else:
            eng.set_loop(*self._loop)
        eng.set_soft_start(SOFT_START_S)
        speed, accel = self._profile
        eng.set_profile(U.rpm_to_counts_per_s(speed), U.rpm_to_counts_per_s(accel))

    def set_gains(self, main: int, speed: int, integ: int, trq: int, torque_limit: int) -> None:
        """Loop gains and torque limit on the engine's 1..127 scale (127 = peak current)."""
        self._gains = (main, speed, integ, trq, torque_limit)
        self._loop = None
        self._apply()

    def set_loop(self, kp: float, speed_bw: float, integ_zero: float, filter_a: float,
                 torque_fraction: float) -> None:
        """Loop coefficients in physical units (:meth:`ServoEngine.set_loop`), for a family
        whose gains are not on the engine's 1..127 scale (YZ-AIM, docs/tuning.md)."""
        self._loop = (kp, speed_bw, integ_zero, filter_a, torque_fraction)
        self._apply()

    @property
    def loop(self) -> tuple[float, float, float, float, float]:
        """The loop coefficients in use (:meth:`set_loop`)."""
        return self._engine.loop

    def set_feedback(self, *, encoder_q: float, velocity_ff: float, accel_ff: bool) -> None:
        """The family's encoder (engine counts per count) and feed-forward (docs/tuning.md)."""
        eng = self._engine
        eng.encoder_q = float(encoder_q)
        eng.velocity_ff = float(velocity_ff)
        eng.accel_ff = bool(accel_ff)
        eng.enc_prev = eng.encoder_counts()
        eng.wake()

    @property
    def gains(self) -> tuple[int, int, int, int, int]:
        return self._gains

    def set_profile(self, speed_rpm: float, accel_rpm_s: float) -> None:
        """Cruise speed (rpm) and acceleration (rpm/s) of every generated motion."""
        self._profile = (float(speed_rpm), float(accel_rpm_s))
        self._apply()

    # ---------------------------------------------------------------- servo
    @property
    def servo_free(self) -> bool:
        return self._free

    def enable(self) -> None:
        """Servo on: the position loop holds where the shaft is."""
        self._free = False
        self._apply_servo()

    def disable(self) -> None:
        """Servo off: the motor coasts."""
        self._free = True
        self._apply_servo()

    def _apply_servo(self) -> None:
        self._switch_servo(Servo.FREE if self._free else Servo.POSITION)
        self._engine.wake()

    # ---------------------------------------------------------------- motion
    def move_to_counts(self, counts: float) -> bool:
        """Absolute move to ``counts`` from the origin on the profile's trapezoid."""
        if self._free:
            return False
        self._engine.go_to(self._origin + counts, 0.0)
        return True

    def halt(self) -> bool:
        """Emergency stop: the reference stops where it is now (servo stays on)."""
        if self._free:
            return False
        self._engine.freeze_reference()
        return True

    def follow_counts(self, counts: float, seconds: float) -> bool:
        """Interpolated motion: the reference moves by ``counts`` evenly over ``seconds``,
        no curve; adds to what is left of the last one."""
        if self._free:
            return False
        self._engine.ext_move(counts, seconds)
        return True

    def run_speed(self, rpm: float) -> bool:
        """Ramp at the profile's acceleration to ``rpm`` and hold it; 0 brakes and holds."""
        if self._free:
            return False
        self._engine.run_speed(U.rpm_to_counts_per_s(rpm), 0.0)
        return True

    @property
    def target_counts(self) -> float:
        """Where the commanded motion ends (counts from the origin; the reference if none)."""
        eng = self._engine
        if eng.ref_mode == Ref.GEN and eng.path is None:
            end = eng.gT
        elif eng.ref_mode == Ref.EXT:
            end = eng.ref + eng.ext_step * eng.ext_left
        else:
            end = eng.ref
        return end - self._origin


    # ---------------------------------------------------------------- time
    def advance(self, seconds: float) -> None:
        self.advance_to(self.time + seconds)

    def advance_to(self, t: float) -> None:
        """Run every control period up to simulated time ``t``."""
        if t <= self.time:
            return
        self.time = t
        self._run_periods(math.floor(t * K.CONTROL_HZ + 1e-6) - self._engine.steps)

