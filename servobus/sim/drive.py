"""VirtualDrive: the protocol-free drive core every simulator front end sits on.

Front ends (DYN232M line, DYN CAN nodes, ...) translate packets into calls on this class;
they never touch its internals. Units at this API:

* motion commands take *command units* (the protocol's numbers): point-to-point distance
  moves ``command x 4096 / GEAR_NUM x 4`` encoder counts;
* ``position`` is in encoder counts (65,536 per revolution), ``speed_rpm`` in rpm,
  ``torque_current`` in the DYN232M relative unit;
* time is simulated seconds: ``advance(dt)`` steps as fast as the CPU allows (tests);
  servers call ``advance_to(wall_clock - t0)`` to run in real time.

Methods that command motion return False when the command was ignored (alarm latched,
servo free, invalid value); the front end decides what the wire says about that.
"""

from __future__ import annotations

from collections.abc import Callable

from servobus.drive import params as P
from servobus.drive import units as U
from servobus.drive.registers import AlarmCode, DriveConfig, DriveStatus, ServoMode
from servobus.sim.eeprom import EepromStore

AlarmListener = Callable[["VirtualDrive", AlarmCode], None]

CONTROL_HZ = 4_000  # fixed control period; see servobus.sim docs
DEFAULT_AXIS_IDS = (1, 2, 3)  # drive ids of X, Y, Z for broadcast interpolation


class VirtualDrive:
    """One simulated DYN2-class drive + motor. Not thread-safe: one event loop owns it."""

    def __init__(
        self,
        drive_id: int = 0,
        *,
        model: str = U.DEFAULT_MODEL,
        eeprom: EepromStore | None = None,
        axis_ids: tuple[int, int, int] = DEFAULT_AXIS_IDS,
    ) -> None:
        self.model = U.MODELS[model]
        self.eeprom = eeprom if eeprom is not None else EepromStore()
        self.eeprom.setdefault_drive(drive_id)
        self.axis_ids = axis_ids
        self.alarm_listeners: list[AlarmListener] = []
        self.time = 0.0
        self._power_on()

    # ---------------------------------------------------------------- lifecycle
    def _power_on(self) -> None:
        """State at power-on: RAM from EEPROM, alarms cleared, relative position 0."""
        self._ram: dict[str, int] = dict(self.eeprom.params)
        self._config = DriveConfig.from_byte(self.eeprom.config)
        self._alarm = AlarmCode.NONE
        self._crc_notice = False
        self._pos = 0.0  # motor position, counts
        self._vel = 0.0  # counts/s
        self._target = 0.0  # commanded end position, counts
        self._speed_cmd: float | None = None  # counts/s in constant-speed mode
        self._busy = False
        self._wave_amp = 0
        self._wave_hz = 0
        self._line_words: list[int] = []
        self._arc_words: list[int] = []

    def reset(self) -> None:
        """Power cycle (also the DYN232M General_Read 0x1C selector)."""
        self._power_on()

    # ---------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return self.eeprom.drive_id

    def assign_id(self, new_id: int) -> bool:
        """Takes effect at once and persists (EEPROM)."""
        if not 0 <= new_id <= 126:
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
    def get_param(self, name: str) -> int:
        return self._ram[P.spec(name).name]

    def set_param(self, name: str, value: int, *, ram_only: bool = False) -> bool:
        """Write a parameter; out-of-range writes are ignored and return False."""
        spec = P.spec(name)
        if not spec.valid(value):
            return False
        self._ram[spec.name] = value
        if not ram_only and spec.storage is P.Storage.EEPROM:
            self.eeprom.write_param(spec.name, value)
        return True

    # ---------------------------------------------------------------- registers
    def peek_status(self) -> DriveStatus:
        alarm = self._alarm
        if alarm is AlarmCode.NONE and self._crc_notice:
            alarm = AlarmCode.CHECKSUM
        on_range = U.onrange_to_counts(self._ram["on_range"])
        return DriveStatus(
            on_position=abs(self._target - self._pos) <= on_range and not self._busy,
            servo_free=self.servo_free,
            alarm=alarm,
            motion_busy=self._busy,
        )

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
        if not 0 <= value <= 0x7F:
            return False
        cfg = DriveConfig.from_byte(value & 0x3F)
        self._config = cfg
        self.eeprom.write_config(cfg.to_byte())
        if cfg.free:
            self._stop_motion()
        return True

    @property
    def servo_free(self) -> bool:
        return self._config.free or self._alarm.latching

    @property
    def alarm(self) -> AlarmCode:
        return self._alarm

    def enable(self) -> None:
        self.set_config(self._config.to_byte() & ~0x20)

    def disable(self) -> None:
        self.set_config(self._config.to_byte() | 0x20)

    def trip(self, code: AlarmCode) -> None:
        """Latch an alarm: motor free, commands ignored until reset()."""
        if self._alarm.latching or not code.latching:
            return
        self._alarm = code
        self._stop_motion()
        for listener in list(self.alarm_listeners):
            listener(self, code)

    # ---------------------------------------------------------------- motion
    def _accepts_motion(self) -> bool:
        return not self.servo_free and self._config.servo_mode is ServoMode.POSITION

    def _stop_motion(self) -> None:
        self._speed_cmd = None
        self._busy = False
        self._target = self._pos
        self._vel = 0.0
        self._wave_amp = 0

    def set_origin(self) -> None:
        self._target -= self._pos
        self._pos = 0.0

    def move_absolute(self, command: int) -> bool:
        if not self._accepts_motion():
            return False
        self._speed_cmd = None
        self._target = U.command_to_counts(command, self._ram["gear_num"])
        self._busy = True
        return True

    def move_relative(self, command: int) -> bool:
        if not self._accepts_motion():
            return False
        base = self._target if self._speed_cmd is None else self._pos
        self._speed_cmd = None
        self._target = base + U.command_to_counts(command, self._ram["gear_num"])
        self._busy = True
        return True

    def turn_const_speed(self, rpm: int) -> bool:
        if not self._accepts_motion():
            return False
        self._speed_cmd = U.rpm_to_counts_per_s(rpm)
        self._busy = False
        return True

    def square_wave(self, amplitude: int) -> bool:
        return self._accepts_motion()  # deepened by the drive-core work

    def sine_wave(self, amplitude: int) -> bool:
        return self._accepts_motion()

    def set_wave_frequency(self, hz: int) -> bool:
        self._wave_hz = hz
        return True

    def linear_line_word(self, value: int) -> bool:
        """One of the four broadcast Make_LinearLine words (dX, dY, dZ, feedrate)."""
        self._line_words.append(value)
        if len(self._line_words) < 4:
            return True
        words, self._line_words = self._line_words, []
        axis = self.axis
        if axis is None:
            return True
        return self.move_relative(words[axis])

    def circular_arc_word(self, value: int) -> bool:
        """One of the five broadcast Make_CircularArc words."""
        self._arc_words.append(value)
        if len(self._arc_words) < 5:
            return True
        self._arc_words = []
        return True  # deepened by the drive-core work

    # ---------------------------------------------------------------- readouts
    @property
    def position(self) -> int:
        return round(self._pos)

    @property
    def speed_rpm(self) -> float:
        return U.counts_per_s_to_rpm(self._vel)

    @property
    def torque_current(self) -> int:
        return 0

    # ---------------------------------------------------------------- time
    def advance(self, seconds: float) -> None:
        self.advance_to(self.time + seconds)

    def advance_to(self, t: float) -> None:
        """Kinematic placeholder: trapezoidal tracking of the target / speed command."""
        dt = t - self.time
        if dt <= 0:
            return
        self.time = t
        if self.servo_free:
            return
        gear = self._ram["gear_num"]
        vmax = U.rpm_to_counts_per_s(U.profile_speed_rpm(self._ram["max_speed"], gear))
        amax = U.rpm_to_counts_per_s(U.profile_accel_rpm_s(self._ram["max_accel"], gear))
        steps = max(1, int(dt * CONTROL_HZ))
        h = dt / steps
        for _ in range(steps):
            if self._speed_cmd is not None:
                dv = max(-amax * h, min(amax * h, self._speed_cmd - self._vel))
                self._vel += dv
                self._pos += self._vel * h
                self._target = self._pos
                continue
            err = self._target - self._pos
            stop_dist = self._vel * self._vel / (2 * amax)
            want = vmax if abs(err) > stop_dist else (2 * amax * abs(err)) ** 0.5
            want = want if err > 0 else -want
            dv = max(-amax * h, min(amax * h, want - self._vel))
            self._vel += dv
            self._pos += self._vel * h
            if abs(self._target - self._pos) < 0.5 and abs(self._vel) < amax * h * 2:
                self._pos, self._vel = self._target, 0.0
                self._busy = False
