"""VirtualDrive: the protocol-free drive core every simulator front end sits on.

Front ends (DYN232M line, DYN CAN nodes, ...) translate packets into calls on this class;
they never touch its internals. Units at this API:

* motion commands take *command units* (the protocol's numbers): point-to-point distance
  moves ``command x 4096 / GEAR_NUM x 4`` encoder counts;
* ``position`` is in encoder counts (65,536 per revolution), ``speed_rpm`` in rpm,
  ``torque_current`` in the DYN232M relative unit (``current_a`` in amperes);
* time is simulated seconds: ``advance(dt)`` steps as fast as the CPU allows (tests);
  servers call ``advance_to(wall_clock - t0)`` to run in real time. One fixed control period
  (``CONTROL_HZ``) runs underneath; commands take effect at the next period.

Methods that command motion return False when the command was ignored (alarm latched,
servo free, wrong servo/command mode, invalid value); the front end decides what the wire
says about that. Motion commands are accepted in position servo mode with the RS232 command
mode (manual 4.4: in pulse/analog modes the serial port only sets and reads parameters).

**Commands versus reads, in one place** (``accepts_commands``): while an alarm is latched
(6.1: "All commands including pulse, analog and RS232 will be ignored"), while an absolute
mode drive returns to its zero after power-on (7.3 b2; DYN CAN 6: it "moves to the set
absolute zero position, then starts accepting command") and while the drive is powered off,
every command is ignored and returns False: motion, pulses, parameter / group / config / id
writes, Set_Origin, servo on/off, waves, torque mode. Nothing reaches the EEPROM. Reads are
always answered while powered (6.1: "Power still remains in the logic circuit for drive
diagnostic and drive status reading"); ``reset()`` (the power cycle) always works.

Public additions beyond the DYN232M set (contract for the other front ends and tests):

* ``move_direct(command) -> bool``: DYN CAN Position Direct (0x1C): relative to the current
  target, no S-curve smoothing, limited by Max Speed / Max Accel.
* ``set_speed_accel_group(max_speed, max_accel) -> bool``: DYN CAN Set_Param_Group2. 0 leaves
  a value unchanged; any other value outside 1..127 rejects the whole write (False). The
  first 10 such writes after power-on go to EEPROM, later ones to RAM only.
* ``set_torque_mode(bool)`` / ``torque_command(amps) -> bool``: DYN5 network torque mode
  (RAM only); the current reference is clipped by the torque limit.
  ``set_torque_speed_limit(rpm)``: the torque mode's speed limit (DYN5 0x27; None = none).
* Inputs: ``input_pulses(count, seconds=0.0)`` (pulses spread over ``seconds``; 4 x GEAR_NUM
  per rev; needs CW/CCW or Pulse/Dir command mode), ``input_pulse_levels(samples,
  seconds=0.0)`` (signal-level (pin6, pin4) samples decoded per ``pulse_format``),
  ``set_analog_input(volts)`` (speed 600 rpm/V, torque 1 or 2 A/V, position 0-10 V ->
  0-90 deg x 4096/GEAR_NUM in Analog command mode; > 2.5 V reads as status b6),
  ``set_enable_input(enabled)`` (JP3-11; disabled = free, commands and error cleared).
* Outputs: ``onpos_output`` (None when JP3-9 is BKO), ``alarm_output``, ``zri_output``,
  ``zri_count``, ``brake_released`` (BKO, only when OnRange was 127 at power-on, else None).
* World: ``set_load(inertia=, friction=)``, ``set_disturbance(nm)``, ``set_blocked(bool)``,
  ``set_bus_voltage(volts)`` (> 80 V trips over voltage; the motor's top speed follows the
  bus, see servobus.sim.core.constants), ``set_encoder_fault(bool)`` (lost phase while set),
  ``overheat(temperature_c)``, ``current_a``, ``heat_fraction``, ``temperature_c``,
  ``reference_counts``, ``following_error_counts``.
* Power: ``powered``, ``power_cycle(off_s)`` (off for ``off_s`` simulated seconds, then the
  power-on of ``reset()``), ``supply_dip(volts, seconds)`` (the bus at ``volts`` for a while;
  below the 24 V minimum input (2.5) the drive is off meanwhile and powers on afterwards).
  A powered-off drive answers nothing: front ends skip it (``powered``).

``model`` may be a ``MotorModel`` instance (a motor sized from tables other than the DMM ones).
The YZ-AIM motor does not sit on this class: it has the protocol-free core
(:class:`servobus.sim.core.motor.Motor`) with its own registers and protections, so this
drive has no switches for another vendor's features.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import replace

from servobus.axis.types import Family
from servobus.families.dmm import params as P
from servobus.families.dmm import profile as PR
from servobus.families.dmm import units as U
from servobus.families.dmm.family import DYN2
from servobus.families.dmm.registers import (
    AlarmCode,
    CommandMode,
    DriveConfig,
    DriveStatus,
    ServoMode,
)
from servobus.families.dmm.vocabulary import WAVE_AMPLITUDE_MAX, WAVE_FREQUENCY_MAX_HZ
from servobus.sim.core import capture as _capture
from servobus.sim.core import constants as K
from servobus.sim.core import interp
from servobus.sim.core.engine import Gen, Ref, Servo, ServoEngine
from servobus.sim.core.io import PulseDecoder, PulseFormat, pulse_period
from servobus.sim.core.motor import EngineShaft
from servobus.sim.dmm.eeprom import EepromStore
from servobus.sim.dmm.trace import DriveTrace

AlarmListener = Callable[["VirtualDrive", AlarmCode], None]
PeriodObserver = Callable[["VirtualDrive"], None]

CONTROL_HZ = K.CONTROL_HZ  # fixed control period (see servobus.sim.core.constants)
DEFAULT_AXIS_IDS = (1, 2, 3)  # drive ids of X, Y, Z for broadcast interpolation
#: DYN232M torque readout: relative unit (manual example 10); decision: 1 unit = 1 mA.
_GAIN_PARAMS = ("main_gain", "speed_gain", "int_gain", "trq_cons", "torque_limit")


class VirtualDrive(EngineShaft):
    """One simulated DYN2-class drive + motor. Not thread-safe: one event loop owns it."""

    def __init__(
        self,
        drive_id: int = 0,
        *,
        model: str | U.MotorModel = U.DEFAULT_MODEL,
        eeprom: EepromStore | None = None,
        axis_ids: tuple[int, int, int] = DEFAULT_AXIS_IDS,
        family: Family = DYN2,
    ) -> None:
        self.model = model if isinstance(model, U.MotorModel) else U.MODELS[model]
        self.set_family(family)
        self.eeprom = eeprom if eeprom is not None else EepromStore()
        self.eeprom.setdefault_drive(drive_id)
        self.axis_ids = axis_ids
        self.alarm_listeners: list[AlarmListener] = []
        self.time = 0.0
        self._engine = ServoEngine(self.model)
        self._enable_input = True
        self._analog_v = 0.0
        self._decoder = PulseDecoder()
        self.zri_count = 0
        self._powered = True
        self._encoder_fault = False
        self._line_direction: tuple[float, float, float] | None = None  # the running line
        self._timers: list[tuple[float, int, Callable[[], None]]] = []  # (time, seq, action)
        self._timer_seq = 0
        #: Called after every control period when set (servobus.sim.core.capture records the
        #: drive's 4 kHz trace with it); None runs the periods in one batch.
        self.period_observer: PeriodObserver | None = None
        self._power_on()
        _capture.note_created(DriveTrace(self))

    # ---------------------------------------------------------------- lifecycle
    def _power_on(self) -> None:
        """State at power-on: RAM from EEPROM, alarms cleared, position per config b2."""
        eng = self._engine
        self._ram: dict[str, int] = dict(self.eeprom.params)
        self._config = DriveConfig.from_byte(self.eeprom.config)
        self._alarm = AlarmCode.NONE
        self._crc_notice = False
        self._wave_amp = 0
        self._wave_square = False
        self._wave_hz = 0  # SS_Frequency resets at power-off (DYN CAN 6)
        self._line_words: list[int] = []
        self._arc_words: list[int] = []
        self._group2_writes = 0
        self._feed_scale = 1.0
        self._bko_mode = self._ram["on_range"] == 127  # 4.6: takes effect after power cycle
        self._powered = True
        self._homing = False
        self._line_direction = None
        eng.power_on()
        eng.servo = Servo.FREE
        self._apply_params()
        if self._config.absolute:
            # 7.3 b2: back to the stored zero; the single-turn encoder knows the angle only
            # within one revolution, so the nearest zero (-180..+180 deg) is used.
            rel = (eng.p - self.eeprom.origin + U.COUNTS_PER_REV / 2) % U.COUNTS_PER_REV
            self._origin = eng.p - (rel - U.COUNTS_PER_REV / 2)
        else:
            self._origin = eng.p  # relative mode: reads 0 after power-on
        self._apply_servo()
        if self._config.absolute and eng.servo == Servo.POSITION:
            self._homing = True  # commands are ignored until the zero is reached (7.3)
            self._go(self._origin)

    def reset(self) -> None:
        """Power cycle (also the DYN232M General_Read 0x1C selector): clears a latched alarm."""
        self._timers = [tm for tm in self._timers if tm[2] != self._power_on]
        self._power_on()

    @property
    def powered(self) -> bool:
        return self._powered

    def power_cycle(self, off_s: float = 0.0) -> None:
        """Power off for ``off_s`` simulated seconds (the shaft coasts, nothing answers),
        then power on as ``reset()`` does; 0 is ``reset()`` at once."""
        if off_s <= 0.0:
            self.reset()
            return
        self._power_off()
        self._at(self.time + off_s, self._power_on)

    def _power_off(self) -> None:
        self._powered = False
        self._homing = False
        self._timers = [tm for tm in self._timers if tm[2] != self._power_on]
        self._apply_servo()

    def supply_dip(self, volts: float, seconds: float) -> None:
        """The DC supply at ``volts`` for ``seconds``, then back to where it was. Decision:
        below the 24 V minimum operating input (2.5) the drive is off for the dip and powers
        on when the supply returns (a brown-out is a power cycle); above it the drive keeps
        running with the lower voltage limit (speed falls, following error grows)."""
        before = self.bus_voltage
        off = volts < K.MIN_INPUT_V
        if off:
            self._power_off()
        self.set_bus_voltage(volts)

        def restore() -> None:
            self.set_bus_voltage(before)
            if off:
                self._power_on()

        self._at(self.time + max(0.0, seconds), restore)

    def _at(self, when: float, action: Callable[[], None]) -> None:
        """Run ``action`` when simulated time reaches ``when`` (advance_to splits there)."""
        self._timer_seq += 1
        self._timers.append((when, self._timer_seq, action))
        self._timers.sort(key=lambda tm: (tm[0], tm[1]))

    @property
    def accepts_commands(self) -> bool:
        """False while alarmed, homing in absolute mode or powered off (module docstring)."""
        return self._powered and not self._alarm.latching and not self._homing

    @property
    def homing(self) -> bool:
        """Absolute mode after power-on: returning to the stored zero (commands ignored)."""
        return self._homing

    def _update_homing(self) -> None:
        eng = self._engine
        if self._homing and (eng.servo != Servo.POSITION or not eng.busy):
            self._homing = False
            if self._config.command_mode is CommandMode.ANALOG:
                self._apply_analog()  # the analog position input takes over from the zero

    # ---------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return self.eeprom.drive_id

    def assign_id(self, new_id: int) -> bool:
        """Takes effect at once and persists (EEPROM)."""
        if not 0 <= new_id <= 126 or not self.accepts_commands:
            return False
        self.eeprom.write_id(new_id)
        return True

    @property
    def axis(self) -> int | None:
        """0, 1, 2 for X, Y, Z when this drive's id is one of ``axis_ids``."""
        try:
            return self.axis_ids.index(self.drive_id)
        except ValueError:
            return None

    # ---------------------------------------------------------------- parameters
    def set_family(self, family: Family) -> None:
        """Whose parameter ranges the drive accepts (``set_param``): the family's own table,
        read here once (DYN2: GEAR_NUM 500..16384; DYN5: 1..16384, LINE_NUM 1..4095). The
        drive parameters are the DMM ones; units, storage and defaults stay the DMM table's."""
        self.family = family
        self._ranges = {p.name: (p.minimum, p.maximum) for p in family.params
                        if p.name in P.BY_NAME}

    def param_range(self, name: str) -> tuple[int, int]:
        """(minimum, maximum) this drive accepts for parameter ``name``."""
        spec = P.spec(name)
        return self._ranges.get(spec.name, (spec.minimum, spec.maximum))

    def _valid(self, name: str, value: int) -> bool:
        low, high = self.param_range(name)
        return low <= value <= high

    def get_param(self, name: str) -> int:
        return self._ram[P.spec(name).name]

    def set_param(self, name: str, value: int, *, ram_only: bool = False) -> bool:
        """Write a parameter; out-of-range writes are ignored and return False.

        EEPROM wear: past 1,000,000 writes the value still takes effect (RAM) but no longer
        survives a power cycle (see :mod:`servobus.sim.dmm.eeprom`)."""
        spec = P.spec(name)
        if isinstance(value, bool) or not isinstance(value, int) or not self._valid(name, value):
            return False
        if not self.accepts_commands:
            return False
        self._ram[spec.name] = value
        if not ram_only and spec.storage is P.Storage.EEPROM:
            self.eeprom.write_param(spec.name, value)
        self._apply_params()
        return True

    def set_speed_accel_group(self, max_speed: int, max_accel: int) -> bool:
        """DYN CAN Set_Param_Group2 (see class docstring for the EEPROM quirk)."""
        values = {"max_speed": max_speed, "max_accel": max_accel}
        if any(v != 0 and not self._valid(n, v) for n, v in values.items()):
            return False
        if not self.accepts_commands:
            return False
        to_eeprom = self._group2_writes < K.GROUP2_EEPROM_WRITES
        self._group2_writes += 1
        for name, v in values.items():
            if v:
                self._ram[name] = v
                if to_eeprom:
                    self.eeprom.write_param(name, v)
        self._apply_params()
        return True

    def _apply_params(self) -> None:
        r = self._ram
        self._engine.set_gains(*(r[n] for n in _GAIN_PARAMS))
        self._engine.set_soft_start(U.soft_start_rise_s(r["max_accel"]))
        self._apply_profile()

    def _max_speed_counts(self) -> float:
        """The axis' configured top speed, counts/s (Max Speed)."""
        return PR.speed_counts_per_s(self._ram["max_speed"], self._ram["gear_num"])

    def _apply_profile(self) -> None:
        g = self._ram["gear_num"]
        self._engine.set_profile(PR.speed_counts_per_s(self._ram["max_speed"], g)
                                 * self._feed_scale,
                                 PR.accel_counts_per_s2(self._ram["max_accel"], g))

    # ---------------------------------------------------------------- registers
    def peek_status(self) -> DriveStatus:
        alarm = self._alarm
        if alarm is AlarmCode.NONE and self._crc_notice:
            alarm = AlarmCode.CHECKSUM
        return DriveStatus(
            on_position=self._on_position(),
            servo_free=self.servo_free,
            alarm=alarm,
            motion_busy=self._engine.busy,
            jp3_pin2=self._analog_v > K.JP3_PIN2_HIGH_V,
        )

    def trace_flags(self) -> tuple[bool, bool, bool, bool]:
        """(servo on, motion busy, on position, alarm) as peek_status has them, without
        building a DriveStatus (servobus.sim.dmm.trace reads it every control period)."""
        return (not self.servo_free, self._engine.busy, self._on_position(),
                self._alarm is not AlarmCode.NONE or self._crc_notice)

    def _on_position(self) -> bool:
        eng = self._engine
        if eng.busy or (eng.servo != Servo.FREE and eng.ref_moving):
            return False
        return abs(eng.ref - eng.p) <= U.onrange_to_counts(self._ram["on_range"])

    def read_status(self) -> DriveStatus:
        """Status as a status read reports it; the checksum notice clears once read."""
        status = self.peek_status()
        self._crc_notice = False
        return status

    def note_checksum_error(self) -> None:
        """A packet failed its checksum: not executed, status alarm code 4 until read."""
        self._crc_notice = True

    def read_config(self) -> DriveConfig:
        return self._config

    def set_config(self, value: int) -> bool:
        """Config byte (7.3); stored in EEPROM. b6 is TBD and dropped."""
        if not 0 <= value <= 0x7F or not self.accepts_commands:
            return False
        cfg = DriveConfig.from_byte(value)  # drops the undefined b6
        self._config = cfg
        self.eeprom.write_config(cfg.to_byte())
        self._apply_servo()
        return True

    @property
    def servo_free(self) -> bool:
        return (self._config.free or self._alarm.latching or not self._enable_input
                or not self._powered)

    @property
    def alarm(self) -> AlarmCode:
        return self._alarm

    def enable(self) -> bool:
        """Servo on (General_Read 0x20). Decision: RAM only, to spare the EEPROM."""
        if not self.accepts_commands:
            return False
        self._config = replace(self._config, free=False)
        self._apply_servo()
        return True

    def disable(self) -> bool:
        """Servo off, motor free (General_Read 0x21). RAM only, like enable()."""
        if not self.accepts_commands:
            return False
        self._config = replace(self._config, free=True)
        self._apply_servo()
        return True

    def trip(self, code: AlarmCode) -> None:
        """Latch an alarm: motor free, commands ignored until reset()."""
        if self._alarm.latching or not code.latching or not self._powered:
            return
        self._engine._trip(code)
        self._latch(code)

    def _tripped(self, code: AlarmCode) -> None:
        self._latch(code)

    def _latch(self, code: AlarmCode) -> None:
        self._alarm = code
        self._engine.trip_code = AlarmCode.NONE
        self._apply_servo()
        for listener in list(self.alarm_listeners):
            listener(self, code)

    def _servo_mode(self) -> Servo:
        if self.servo_free:
            return Servo.FREE
        return {ServoMode.SPEED: Servo.SPEED, ServoMode.TORQUE: Servo.TORQUE}.get(
            self._config.servo_mode, Servo.POSITION)

    def _apply_servo(self) -> None:
        if self._switch_servo(self._servo_mode()):
            self._update_homing()
            self._apply_analog()
        self._engine.wake()

    # ---------------------------------------------------------------- motion
    def _accepts_motion(self) -> bool:
        return (self.accepts_commands and not self.servo_free
                and self._config.servo_mode is ServoMode.POSITION
                and self._config.command_mode is CommandMode.RS232)

    def _counts(self, command: float) -> float:
        return U.command_to_counts(command, self._ram["gear_num"])

    def _smoothing(self, distance: float) -> float:
        eng = self._engine
        ta, tc, _ = PR.trapezoid_time(distance, eng.vmax, eng.amax)
        return PR.smoothing_window(2 * ta + tc, ta)

    def _ptp_limits(self) -> None:
        if self._feed_scale != 1.0:
            self._feed_scale = 1.0
            self._apply_profile()

    def _go(self, target: float, *, smooth: bool = True) -> None:
        self._ptp_limits()
        eng = self._engine
        dist = abs(target - eng.ref)
        eng.go_to(target, self._smoothing(dist) if smooth else 0.0)

    def set_origin(self) -> bool:
        """The current motor position becomes 0; stored as the absolute zero (EEPROM)."""
        if not self.accepts_commands:
            return False
        eng = self._engine
        self._origin = eng.p
        self.eeprom.write_origin(round(eng.p) % U.COUNTS_PER_REV)
        return True

    def move_absolute(self, command: int) -> bool:
        if not self._accepts_motion():
            return False
        self._go(self._origin + self._counts(command))
        return True

    def _relative_base(self) -> float:
        eng = self._engine
        if eng.ref_mode == Ref.GEN and eng.path is None and eng.gen == Gen.POS:
            return eng.gT  # DTPU: relative to the running target
        return eng.ref

    def move_relative(self, command: int) -> bool:
        if not self._accepts_motion():
            return False
        self._go(self._relative_base() + self._counts(command))
        return True

    def move_direct(self, command: int) -> bool:
        """DYN CAN Position Direct: relative, no S-curve smoothing, Max Speed/Accel limits."""
        if not self._accepts_motion():
            return False
        self._go(self._relative_base() + self._counts(command), smooth=False)
        return True

    def turn_const_speed(self, rpm: int) -> bool:
        """Ramp at Max Accel to ``rpm`` and hold it; 0 brakes at Max Accel and holds."""
        if not self._accepts_motion():
            return False
        self._ptp_limits()
        self._engine.run_speed(U.rpm_to_counts_per_s(rpm), 0.0)
        return True

    def set_torque_mode(self, torque: bool) -> None:
        """DYN5 Command Mode Switch: torque servo (True) or position/speed servo (False).

        RAM only, like enable(); the current reference restarts at 0 A."""
        if not self.accepts_commands:
            return
        mode = ServoMode.TORQUE if torque else ServoMode.POSITION
        if self._config.servo_mode is not mode:
            self._config = replace(self._config, servo_mode=mode)
            self._apply_servo()

    def torque_command(self, amps: float) -> bool:
        """Torque servo current reference in A (+ = towards + / CW), clipped by the torque
        limit; ignored (False) unless the servo is on in torque mode.

        A network command (DYN5 0x26) bypasses the soft start that filters the DYN2's analog
        torque reference (5.1, Max Acceleration): DYN5 section 7, commands "become effective
        in the servo loop after <=300us. This is true for all position, speed or torque
        commands". The loop takes it at its next period (250 us at 4 kHz); the TrqCons
        filter and the current loop stay, as they are the loop's own (issue 34)."""
        if self.servo_free or self._config.servo_mode is not ServoMode.TORQUE:
            return False
        eng = self._engine
        eng.speed_target = eng.speed_ref = float(amps)
        eng.wake()
        return True

    def set_torque_speed_limit(self, rpm: float | None) -> None:
        """Torque servo speed limit (DYN5 instance 0x27: "The servo drive will not exceed the
        speed set by this parameter when in torque mode"); None removes it.

        The speed loop runs against +-limit in the direction of the torque command and clamps
        the torque: an unloaded motor accelerates with the commanded torque up to the limit
        and holds it there, its current falling to what friction and load take; a load that
        pushes it faster is braked. RAM only; no limit at power-on (the DYN2's analog torque
        mode has none)."""
        if rpm is None:
            self._engine.torque_speed_limit = math.inf
        else:
            self._engine.torque_speed_limit = U.rpm_to_counts_per_s(abs(float(rpm)))
        self._engine.wake()

    @property
    def torque_speed_limit_rpm(self) -> float | None:
        limit = self._engine.torque_speed_limit
        return None if limit == math.inf else U.counts_per_s_to_rpm(limit)

    def square_wave(self, amplitude: int) -> bool:
        return self._wave(amplitude, square=True)

    def sine_wave(self, amplitude: int) -> bool:
        return self._wave(amplitude, square=False)

    def _wave(self, amplitude: int, *, square: bool) -> bool:
        """Runs while SS_Frequency is not 0; amplitude 0 stops.

        Decision: the amplitude is the total swing (4096 = 180 deg, centred on the position
        where the wave started), so the largest square-wave step is 180 deg, the lost-phase
        limit; a +-180 deg reading would make every full-amplitude square wave trip it."""
        if not 0 <= amplitude <= WAVE_AMPLITUDE_MAX or not self._accepts_motion():
            return False
        self._wave_amp, self._wave_square = amplitude, square
        self._update_wave()
        return True

    def set_wave_frequency(self, hz: int) -> bool:
        """SS_Frequency in Hz (shared by both waves); 0 stops the wave."""
        if not 0 <= hz <= WAVE_FREQUENCY_MAX_HZ or not self.accepts_commands:
            return False
        self._wave_hz = hz
        if self._accepts_motion():
            self._update_wave()
        return True

    def _update_wave(self) -> None:
        eng = self._engine
        if self._wave_amp and self._wave_hz:
            self._ptp_limits()
            eng.start_wave(self._wave_square, self._wave_amp * U.WAVE_COUNTS_PER_UNIT / 2,
                           self._wave_hz, None)
        else:
            eng.stop_wave(0.0)

    def linear_line_word(self, value: int) -> bool:
        """One of the four broadcast Make_LinearLine words (dX, dY, dZ, feedrate)."""
        if not self.accepts_commands:
            return False
        self._line_words.append(value)
        if len(self._line_words) < 4:
            return True
        words, self._line_words = self._line_words, []
        axis = self.axis
        if axis is None:
            return True
        if not self._accepts_motion():
            return False
        return self._run_path(interp.line_path(words, axis, self._counts(1)))

    def circular_arc_word(self, value: int) -> bool:
        """One of the five broadcast Make_CircularArc words."""
        if not self.accepts_commands:
            return False
        self._arc_words.append(value)
        if len(self._arc_words) < 5:
            return True
        words, self._arc_words = self._arc_words, []
        axis = self.axis
        if axis is None:
            return True
        if not self._accepts_motion():
            return False
        plane, _ = PR.unpack_arc_word(words[4])
        if plane in interp.PLANES and axis not in interp.PLANES[plane]:
            self._line_direction = None  # the path every axis shares is no longer a line
            return True  # the third axis does not move
        return self._run_path(interp.arc_path(words, axis, self._counts(1)))

    def _run_path(self, path: interp.AxisPath | None) -> bool:
        """Start a path where the reference is now (its end point is exact) and carry the
        speed under way over (DTPU, 7.5; servobus.sim.core.engine.ServoEngine.go_path).

        Decision: a line that interrupts a running line starts at the old line's path speed
        projected on its direction (every axis drive runs every line, so all axes compute
        the same start and stay on the path; a line in the same direction keeps cruising).
        Any other path starts from rest. What the path does not take over of this axis'
        reference speed is handed over and decays within Max Accel. A point-to-point move or
        constant speed during a path continues from the axis reference's speed (the S-curve
        generator's own DTPU)."""
        if path is None:
            return False
        eng = self._engine
        start_speed = 0.0
        old = self._line_direction
        if old is not None and path.direction is not None and eng.path is not None:
            cosine = sum(a * b for a, b in zip(old, path.direction, strict=True))
            start_speed = max(0.0, eng.path_speed * cosine)
        self._line_direction = path.direction
        axis_speed = eng.vff if eng.servo == Servo.POSITION else 0.0
        self._feed_scale = path.feed_scale
        self._apply_profile()
        start = eng.ref
        at = path.at

        def to_counts(s: float) -> float:
            return start + at(s)

        eng.go_path(path.length, to_counts, self._smoothing(path.length),
                    start_speed=start_speed, handover=axis_speed - start_speed * path.slope,
                    speed_limit=self._max_speed_counts())
        return True

    # ---------------------------------------------------------------- inputs (JP3)
    @property
    def pulse_format(self) -> PulseFormat:
        return self._decoder.format

    @pulse_format.setter
    def pulse_format(self, fmt: PulseFormat | str) -> None:
        """Pulse/Dir or A/B in command mode 2 (the config byte cannot tell them apart, DMMDRV
        can); command mode 1 always decodes CW/CCW."""
        self._decoder.format = PulseFormat(fmt)

    def _accepts_pulses(self) -> bool:
        return (self.accepts_commands and not self.servo_free
                and self._config.servo_mode is ServoMode.POSITION
                and self._config.command_mode in (CommandMode.CW_CCW, CommandMode.PULSE_DIR))

    def input_pulses(self, count: int, seconds: float = 0.0) -> bool:
        """``count`` signed pulses spread evenly over ``seconds`` (0 = all at once)."""
        if not self._accepts_pulses():
            return False
        self._engine.ext_move(self._counts(count), seconds)
        return True

    def input_pulse_levels(self, samples: Iterable[tuple[bool, bool]],
                           seconds: float = 0.0) -> int:
        """Decode (pin 6, pin 4) level samples; returns the pulses taken (0 if ignored)."""
        count = self._decode(samples)
        return count if count and self.input_pulses(count, seconds) else 0

    def _decode(self, samples: Iterable[tuple[bool, bool]]) -> int:
        dec = self._decoder
        if self._config.command_mode is CommandMode.CW_CCW:
            saved, dec.format = dec.format, PulseFormat.CW_CCW
            count = dec.feed(samples)
            dec.format = saved
            return count
        return dec.feed(samples)

    def input_pulse_train(self, fmt: PulseFormat | str, count: int,
                          seconds: float = 0.0) -> int:
        """A train of ``count`` signed pulses in ``fmt`` on JP3-3..6 over ``seconds``, as
        the drive decodes it (its own format: a train in another format counts what that
        decoder sees, as on a miswired machine). Returns the pulses taken (0 if ignored).

        Decoded one period at a time: the train is periodic, so the first period and one
        steady period give the count of any length without sampling every edge."""
        if count == 0:
            return 0
        period = pulse_period(PulseFormat(fmt), count > 0)
        first = self._decode(period)
        steady = self._decode(period) if abs(count) > 1 else 0
        total = first + (abs(count) - 1) * steady
        return total if total and self.input_pulses(total, seconds) else 0

    def set_analog_input(self, volts: float) -> None:
        """JP3-2 analog reference (clamped to the +-12 V input limit)."""
        lim = K.ANALOG_INPUT_MAX_V
        self._analog_v = max(-lim, min(lim, float(volts)))
        self._apply_analog()

    @property
    def analog_input(self) -> float:
        return self._analog_v

    @property
    def enable_input(self) -> bool:
        """JP3-11 ENA as last set: True = drive enabled (no disable signal)."""
        return self._enable_input

    def _apply_analog(self) -> None:
        eng = self._engine
        if self._homing:
            return  # the level is applied once the zero is reached (_update_homing)
        v = self._analog_v
        if eng.servo == Servo.SPEED:
            eng.speed_target = U.rpm_to_counts_per_s(v * U.ANALOG_SPEED_RPM_PER_V)
        elif eng.servo == Servo.TORQUE:
            eng.speed_target = v * self.model.torque_per_volt_a
        elif (eng.servo == Servo.POSITION
              and self._config.command_mode is CommandMode.ANALOG):
            deg = max(0.0, min(10.0, v)) / 10.0 * U.ANALOG_POSITION_DEG_AT_10V
            eng.ext_set(self._origin + deg / 360.0 * U.COUNTS_PER_REV
                        * U.gear_ratio(self._ram["gear_num"]))
        eng.wake()

    def set_enable_input(self, enabled: bool) -> None:
        """JP3-11 ENA: False = disabled (motor coasts, commands and position error cleared)."""
        self._enable_input = bool(enabled)
        self._apply_servo()

    # ---------------------------------------------------------------- outputs (JP3)
    @property
    def onpos_output(self) -> bool | None:
        """JP3-9 ONPOS: True (HIGH) when on position; None when the pin is BKO."""
        return None if self._bko_mode else self._on_position()

    @property
    def brake_released(self) -> bool | None:
        """JP3-9 BKO (OnRange 127 at power-on): True = ON/LOW = brake released (servo on)."""
        return (not self.servo_free) if self._bko_mode else None

    @property
    def alarm_output(self) -> bool:
        """JP3-8 ALM: True (transistor ON, LOW) while an alarm is latched."""
        return self._alarm.latching and self._powered

    @property
    def zri_output(self) -> bool:
        """JP3-10 ZRI: True (LOW) while the shaft is at the encoder's zero index."""
        if not self._powered:
            return False  # every output transistor is off (HIGH) without power
        a = self._engine.p % U.COUNTS_PER_REV
        return min(a, U.COUNTS_PER_REV - a) <= K.ZRI_HALF_WIDTH_COUNTS

    # ---------------------------------------------------------------- world (simulator)
    # set_load, set_disturbance, set_blocked: EngineShaft
    def _apply_load(self) -> None:
        self._apply_params()

    def world(self) -> dict[str, float | bool]:
        """The simulated world around the drive as set by set_load, set_disturbance,
        set_blocked and set_encoder_fault (the control channel's state readout)."""
        eng = self._engine
        return {"load_inertia_kgm2": eng.load_inertia, "load_friction_nm": eng.load_friction,
                "load_torque_nm": eng.disturbance, "blocked": eng.blocked,
                "encoder_fault": self._encoder_fault}

    @property
    def bus_voltage(self) -> float:
        return self._engine.bus_voltage

    def set_bus_voltage(self, volts: float) -> None:
        """DC bus; above 80 V the over-voltage alarm trips (2.5)."""
        self._engine.set_bus_voltage(volts)
        self._check_faults()

    def set_encoder_fault(self, faulty: bool) -> None:
        """Encoder feedback lost (cable, sensor): the drive cannot resolve the motor position
        and trips lost phase (6.1: "The encoder has detected an irresolvable position error")
        at once, and again after every power cycle while the fault stays."""
        self._encoder_fault = bool(faulty)
        self._check_faults()

    @property
    def encoder_fault(self) -> bool:
        return self._encoder_fault

    def _check_faults(self) -> None:
        if self._engine.bus_voltage > U.OVER_VOLTAGE_V:
            self.trip(AlarmCode.OVER_VOLTAGE)
        elif self._encoder_fault:
            self.trip(AlarmCode.LOST_PHASE)

    # ---------------------------------------------------------------- readouts (EngineShaft)

    @property
    def torque_reference_a(self) -> float:
        """The current the servo loop commanded in its last period (its torque reference,
        before the TrqCons filter), A; 0 with the servo free."""
        eng = self._engine
        return eng.tq_cmd * eng.inv_kt if eng.servo != Servo.FREE else 0.0

    @property
    def torque_current(self) -> int:
        return round(self.current_a * U.DYN232_TORQUE_UNITS_PER_A)

    @property
    def heat_fraction(self) -> float:
        """I^2 t thermal state relative to the over-power trip level (1.0 trips)."""
        return self._engine.heat / self._engine.heat_trip

    @property
    def temperature_c(self) -> float:
        """Power stage temperature, read from the I^2 t state (constants.OVERHEAT_C)."""
        return K.AMBIENT_C + (K.OVERHEAT_C - K.AMBIENT_C) * self.heat_fraction

    def overheat(self, temperature_c: float) -> None:
        """The power stage at ``temperature_c`` (from outside: a blocked heat sink, a hot
        cabinet); at or above the trip temperature the overheat alarm trips at once. It then
        cools with the I^2 t time constant, like a warm drive across a power cycle (a reset
        before it has cooled below the trip level trips again, 6.1: fix the cause first)."""
        eng = self._engine
        frac = (float(temperature_c) - K.AMBIENT_C) / (K.OVERHEAT_C - K.AMBIENT_C)
        eng.heat = max(0.0, frac) * eng.heat_trip
        eng.wake()
        if frac >= 1.0:
            self.trip(AlarmCode.OVERHEAT)

    @property
    def reference_counts(self) -> float:
        """Where the reference (Pset) is now, counts from the origin."""
        return self._engine.ref - self._origin

    @property
    def following_error_counts(self) -> float:
        """Pset - Pmotor in counts (positive: the motor lags a positive move)."""
        eng = self._engine
        return eng.ref - eng.p

    # ---------------------------------------------------------------- time
    def advance(self, seconds: float) -> None:
        self.advance_to(self.time + seconds)

    def advance_to(self, t: float) -> None:
        """Run every control period up to simulated time ``t`` (and any timed event)."""
        while self._timers and self._timers[0][0] <= t:
            when, _, action = self._timers.pop(0)
            self._step_to(when)
            action()
        self._step_to(t)

    def _step_to(self, t: float) -> None:
        if t <= self.time:
            return
        self.time = t
        eng = self._engine
        n = math.floor(t * CONTROL_HZ + 1e-6) - eng.steps
        if n <= 0:
            return
        self._check_faults()
        rev0 = math.floor(eng.p / U.COUNTS_PER_REV)
        self._run_periods(n)
        self._update_homing()
        self.zri_count += abs(math.floor(eng.p / U.COUNTS_PER_REV) - rev0)
