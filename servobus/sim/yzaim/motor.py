"""The virtual YZ-AIM integrated servo motor, protocol-free: a register file on the drive core.

Front ends (EasyCan nodes, the Modbus RTU line) turn frames into :meth:`YzaimMotor.read_words`,
:meth:`write_words`, :meth:`emergency_stop`, :meth:`clear_position` and
:meth:`write_position_cache`; registers, ranges and units are the family table's
(servobus.families.yzaim.registers), the physics is the protocol-free
:class:`servobus.sim.core.motor.Motor` (motor sizing in servobus.sim.yzaim.physics); the
YZ-AIM protections are modelled here. Positions here are YZ-AIM counts (32,768 per
revolution), speeds rpm, currents A; time is simulated seconds (``advance``/``advance_to``,
driven by a RealtimeClock in servers).

Behaviour, with the manual's sections (docs/yzaim.md) and servobus decisions where it is silent:

* **Communication control** (0x00, 4.8): while modbus_enable is 0 every write except to 0x00
  is ignored (4.4: "you must first enable the modbus"); reads always work. It powers up as 1
  when gear_numerator 0 is saved, else 0. ``communication=True`` (the default of the
  simulators) gives a fresh EEPROM gear_numerator 0, the setup 5.4c prescribes for
  communication control; ``False`` gives the table's factory values.
* **Writes that are not applied**: a read-only register, a value outside the table's range,
  anything while modbus_enable is 0. The register keeps its value; the front end's write
  reply shows what the register holds afterwards (5.5 has no error code for a bad value).
  An address past 0x1D raises :class:`MotorRefused` (ILLEGAL_ADDRESS), and so does a
  second position-cache write within one 2 ms cycle (TOO_FAST, 5.5 code 0x05).
* **32-bit pairs** (0x0C/0x0D, 0x16/0x17, 0x1A/0x1B; low word at the lower address): the
  action runs when the low word is written, alone or with the high word in the same write;
  a high word written alone is latched for the next low-word write, then cleared.
* **Position mode** (0x19 = 0): 0x16 moves to an absolute position, 0x0C moves by a distance
  from the current target (two quick increments add up); the drive's trapezoid at 0x02 (capped
  by the model's maximum speed) and 0x03 below 60000, none above (4.1). With gear_numerator 0,
  writing 0 to 0x16 clears the absolute position and 0 to 0x0C stops (4.7). Reading 0x16/0x17
  gives the current position, 0x0C/0x0D the last increment written.
* **Speed mode** (0x19 = 3, switched at once; the PWM input is not simulated): the motor runs
  at 0x02 rpm, direction from dir_polarity 0x09 (0: increasing position, as an open DIR input
  turns clockwise at polarity 0), ramping at 0x03. Position writes are ignored in speed mode;
  leaving it ramps to a stop and holds; an emergency stop ends it (0x19 then reads 0).
* **Enable** (0x01): 0 frees the motor and clears a latched alarm, 1 energises it (refused
  while an alarm is latched). An alarm that stops the motor frees it and holds until 0x01 is
  written 0 (then 1) or the power is cycled (2.3 says only "downtime").
* **Limits and alarms**, checked every 2 ms: at standstill (below 5 rpm) the current is
  limited to 0x18 x peak (609 = 60.9 %), else to 0x1D (mA). Stall 0x14: at standstill on
  the 0x18 limit for the units digit of 0x18 in seconds (0: never). Over-current 0x11: on the
  0x1D limit for its units digit in seconds (0: hold the limit). Over-voltage 0x12: supply
  above the model's range + 10 %. Battery warning 0x13 (multi-turn models, motor keeps
  running) while ``set_battery(False)``.
* **Synchronous cache** (0x1A-0x1C, 5.4c/d): a cache value written since the last take is
  pending. With 0x1C = 0 it only waits. Writing 0x1C > 0 (not 255) is the synchronisation
  signal (5.2 0x1B): a pending cache is taken at once and the drive's 2 ms time base
  restarts there (at the instant the frame arrived, ``at=``, when a front end handles it
  late), so motors loaded first and then signalled start together (a power-on cache of 0 is
  never pending, so the signal alone never moves a motor). From then on the newest cache
  value is taken every 2 ms: with the drive's curve below 60000 (5.4c, "accumulating": it
  may lag), at 60000 and above interpolated linearly over the next 2 ms cycle at no more
  than the speed limit 0x02 (5.4d, "no lag"). 0x1C = 255 takes the cache on each
  ``dir_edge()``. While 0x1C is not 0, a cache write while the previous one is still
  pending is refused (TOO_FAST), not stored; a write handled after the tick of its cycle
  is taken at once. Frames are judged by when they reached the bus (``at=``): a second
  frame that arrived before the tick that takes the first is refused, also when the motor
  handles both after that tick.
* **Cache frames read together** (servobus decision, ``batch=``): the socketcand hub reads
  a client's TCP data in chunks and stamps every frame of one chunk with the chunk's
  instant; when the simulator is loaded, one chunk holds frames the host sent in several
  2 ms cycles, and nothing tells when each reached the bus (on a real bus no two frames
  arrive at one instant: each takes ~100 us on the wire). A cache frame with the same
  ``batch`` key as this motor's previous cache frame is therefore not refused as a
  second write within one cycle (0x1C not 255): it is queued, and the queue is taken one
  value per 2 ms tick, in order; a cache frame that comes while the queue is not empty
  joins it (it reached the bus after them). At most ``MAX_QUEUED_CACHE`` wait (more: TOO_FAST). A
  write to 0x1C first takes the queued values at once, in order (they reached the bus
  before it). The price: a host that really writes two cache frames for one motor in one
  TCP write within one cycle is not refused over socketcand (other buses, and frames of
  different chunks, are judged by arrival as above).
* **Save** (0x14): 1 stores every saved register at once (reads 2 afterwards), 3 also the
  single-turn origin (reads 2); 0 and 2 are only stored. The write's reply carries the value
  written (5.4a: ``FF 06 14 01 01 00`` is answered ``01 06 14 01 01 00``; 1 = "saving
  parameters", the register's state while the write executes); reads give 2 afterwards. A
  new device address 0x15 takes effect at the next power cycle.
* **Power cycle**: RAM from EEPROM; multi-turn models (57AIM) keep their position (battery),
  single-turn models read the angle within one turn; special functions 6/8 then go to 0 and
  10..32768 to that angle within the turn; 1, 2, 4, 7 and 9 are stored, not simulated.
* **Measurements**: system current 0x0F = 0.05 A + |motor current| x duty (duty = |speed| /
  maximum speed + 0.1, at most 1); temperature 0x12 = 25 degC + 45 degC x (I^2 filtered over
  60 s) / rated^2; output PWM 0x13 = motor current / peak x 32767.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Hashable, Sequence
from enum import IntEnum

from servobus.axis.capture import status_bits
from servobus.axis.types import motion_state
from servobus.errors import ServobusError
from servobus.families.yzaim import registers as yzaim
from servobus.sim.core import capture
from servobus.sim.core.motor import Motor
from servobus.sim.yzaim import physics as phys
from servobus.sim.yzaim.store import YzaimStore

TICK_S = yzaim.SYNC_CYCLE_S  # limits, alarms and the synchronous cache: every 2 ms
STANDSTILL_RPM = 5.0
SATURATED = 0.95  # current at >= 95 % of its limit counts as "on the limit"
IDLE_SUPPLY_A = 0.05
DUTY_FLOOR = 0.1
AMBIENT_C = 25.0
RATED_RISE_C = 45.0
THERMAL_TAU_S = 60.0
MAX_QUEUED_CACHE = 64  # cache frames read together waiting (the hub's receive FIFO size)
OVER_VOLTAGE_MARGIN = 1.1
PWM_FULL_SCALE = 32767

_R = yzaim.BY_NAME
_ABS = yzaim.PAIR_BY_NAME["absolute_position"]
_INC = yzaim.PAIR_BY_NAME["incremental_position"]
_CACHE = yzaim.PAIR_BY_NAME["position_cache"]
_GAIN_REGISTERS = ("position_loop_kp", "speed_loop_kp", "speed_loop_integration_time")
_PROFILE_REGISTERS = ("target_speed", "acceleration")
_LIVE = ("alarm_code", "system_current", "motor_speed", "supply_voltage", "drive_temperature",
         "output_pwm", "save_flag")


class Refusal(IntEnum):
    """Why the motor refuses a request outright (protocol front ends map these to codes)."""

    ILLEGAL_ADDRESS = 0x02
    TOO_FAST = 0x05


class MotorRefused(ServobusError):
    def __init__(self, reason: Refusal, message: str) -> None:
        super().__init__(message)
        self.reason = reason


class YzaimMotor:
    """One simulated YZ-AIM motor. Not thread-safe: one event loop owns it."""

    def __init__(self, address: int = 1, *, model: str = yzaim.DEFAULT_MODEL,
                 store: YzaimStore | None = None, communication: bool = True) -> None:
        self.model = yzaim.model(model)
        self.store = store if store is not None else YzaimStore(key=str(address))
        if not self.store.loaded:
            self.store.registers["device_address"] = _R["device_address"].check(address)
            if communication:
                self.store.registers["gear_numerator"] = 0
        core = phys.core_model(self.model)
        self.drive = Motor(core)  # the motor and its position loop (engine counts)
        self.drive.set_feedback(encoder_q=phys.CORE_PER_COUNT, velocity_ff=0.0, accel_ff=False)
        capture.note_front(self)  # sim:// traces this motor (its address and counts)
        self.peak_a = core.peak_current_a
        self.refused_writes = 0  # writes not applied (range, access, modbus_enable 0)
        self.refused_cache = 0  # cache writes within one cycle (TOO_FAST)
        self.supply_v = (self.model.supply_v[0] + self.model.supply_v[1]) / 2
        self.battery_ok = True
        self._i2 = 0.0
        # YZ-AIM counts at core position 0: the recorded position (a single-turn encoder
        # reads only its angle within the turn at power-on, as in power_cycle)
        recorded = self.store.position or 0
        self._offset = float(recorded if self.model.multi_turn
                             else recorded % yzaim.COUNTS_PER_REV)
        self._power_on()

    # ---------------------------------------------------------------- lifecycle
    def _power_on(self) -> None:
        ram = yzaim.defaults()
        ram.update(self.store.registers)
        ram["modbus_enable"] = 1 if ram["gear_numerator"] == 0 else 0
        ram["output_enable"] = 1
        self._ram = ram
        self.address = ram["device_address"]
        self._save_flag = yzaim.SaveFlag.NOT_SAVED
        self._latched_high: dict[int, int] = {}
        self._alarm = 0
        self._stall_t = self._over_t = 0.0
        self._standstill = True
        self._torque_param = 0
        self._speed_mode = False
        self._cache_pending = False
        self._cache_queue: deque[int] = deque()  # cache frames read together, one per tick
        self._cache_batch: Hashable | None = None  # the batch key of the last cache frame
        self._cache_due = -math.inf  # when the last cache value is (was) taken, by arrival
        self._next_tick = self.drive.time + TICK_S
        self._at = self.drive.time  # arrival time of the frame being executed
        self._save_reply: int | None = None  # the save-flag word of the write in progress
        drive = self.drive
        drive.disable()
        drive.enable()
        self._apply_gains()
        self._apply_profile()
        self._apply_limits()
        self._apply_mode()
        self._power_on_function()

    def power_cycle(self) -> None:
        """Power off and on: the position is recorded (multi-turn) and RAM reloads."""
        here = self.position
        self.store.record_position(here)
        if not self.model.multi_turn:  # single-turn encoder: only the angle survives
            self._offset += (here % yzaim.COUNTS_PER_REV) - here
        self._power_on()

    def _power_on_function(self) -> None:
        sf = self._ram["special_function"]
        turn = math.floor(self.position / yzaim.COUNTS_PER_REV) * yzaim.COUNTS_PER_REV
        if sf in (yzaim.SpecialFunction.BATTERY_RETURN_TO_ZERO,
                  yzaim.SpecialFunction.BRAKE_MULTI_TURN_RETURN_TO_ORIGIN):
            self._move_to(0)
        elif yzaim.POWER_ON_ANGLE_MIN <= sf <= yzaim.POWER_ON_ANGLE_MAX:
            self._move_to(turn + sf)

    # ---------------------------------------------------------------- readouts
    @property
    def time(self) -> float:
        return self.drive.time

    @property
    def position(self) -> int:
        """Absolute position, counts (32,768 per revolution)."""
        return round(self.drive.position / phys.CORE_PER_COUNT + self._offset)

    @property
    def target(self) -> int:
        """Where the current motion ends, counts."""
        return round(self.drive.target_counts / phys.CORE_PER_COUNT + self._offset)

    @property
    def speed_rpm(self) -> float:
        return self.drive.speed_rpm

    @property
    def current_a(self) -> float:
        return self.drive.current_a

    @property
    def alarm(self) -> yzaim.Alarm:
        return yzaim.alarm(self._alarm)

    @property
    def enabled(self) -> bool:
        return not self.drive.servo_free

    @property
    def speed_mode(self) -> bool:
        return self._speed_mode

    def registers(self) -> dict[str, int]:
        """Every register's raw value as a read would give it."""
        return {r.name: self._raw(r) for r in yzaim.REGISTERS}

    # ---------------------------------------------------------------- register access
    def _check_span(self, address: int, count: int) -> None:
        if count < 1 or address < 0 or address + count > yzaim.REGISTER_COUNT:
            raise MotorRefused(
                Refusal.ILLEGAL_ADDRESS,
                f"registers 0x{address:02X}..0x{address + count - 1:02X} are outside "
                f"0x00..0x{yzaim.REGISTER_COUNT - 1:02X}")

    def read_words(self, address: int, count: int = 1) -> tuple[int, ...]:
        """16-bit words of ``count`` registers from ``address`` (MotorRefused past 0x1D)."""
        self._check_span(address, count)
        return tuple(self.read_word(a) for a in range(address, address + count))

    def read_word(self, address: int) -> int:
        self._check_span(address, 1)
        reg = yzaim.BY_ADDRESS[address]
        return reg.word(self._raw(reg))

    def _raw(self, reg: yzaim.Register) -> int:
        name = reg.name
        if address_in_pair(reg.address, _ABS):
            return _pair_word(self.position, reg.address - _ABS.low)
        if name in _LIVE:
            return self._live(name)
        return self._ram[name]

    def _live(self, name: str) -> int:
        speed = self.speed_rpm
        current = self.current_a
        match name:
            case "alarm_code":
                return self._alarm
            case "motor_speed":
                return _clip(_R[name], speed * _R[name].per_unit)
            case "system_current":
                duty = min(1.0, abs(speed) / self.model.max_rpm + DUTY_FLOOR)
                amps = IDLE_SUPPLY_A + abs(current) * duty
                return _clip(_R[name], amps * _R[name].per_unit)
            case "supply_voltage":
                return _clip(_R[name], self.supply_v * _R[name].per_unit)
            case "drive_temperature":
                rise = RATED_RISE_C * self._i2 / self.model.current_a ** 2
                return _clip(_R[name], AMBIENT_C + rise)
            case "output_pwm":
                return _clip(_R[name], current / self.peak_a * PWM_FULL_SCALE)
            case "save_flag":
                return int(self._save_flag)
        raise KeyError(name)  # pragma: no cover

    def write_words(self, address: int, words: Sequence[int], *,
                    at: float | None = None) -> tuple[int, ...]:
        """Write consecutive registers; returns what they hold afterwards (see module doc).

        ``at``: the simulated time the frame reached the motor, when the front end handles
        it later than that (the 2 ms cycle it belongs to; default: now)."""
        self._check_span(address, len(words))
        self._at = self.time if at is None else min(at, self.time)
        self._save_reply = None
        for w in words:
            if not 0 <= w <= yzaim.WORD_MAX:
                raise ValueError(f"register word {w} is outside 0..{yzaim.WORD_MAX}")
        end = address + len(words)
        if (self._ram["modbus_enable"] and address <= _CACHE.low < end
                and self._cache_is_pending()):
            self._refuse_cache()
        i = 0
        while i < len(words):
            addr = address + i
            pair = yzaim.PAIR_BY_LOW.get(addr)
            if pair is not None and i + 1 < len(words):
                self._write_pair(pair, words[i], words[i + 1])
                i += 2
                continue
            high_of = yzaim.PAIR_BY_LOW.get(addr - 1)
            if high_of is not None and address_in_pair(addr, high_of):
                self._latched_high[high_of.low] = words[i]
            elif pair is not None:
                self._write_pair(pair, words[i], self._latched_high.get(pair.low, 0))
            else:
                self._write_register(yzaim.BY_ADDRESS[addr], words[i])
            i += 1
        held = self.read_words(address, len(words))
        if self._save_reply is not None:  # an accepted save: its reply shows what was written
            at_flag = _R["save_flag"].address - address
            held = (*held[:at_flag], self._save_reply, *held[at_flag + 1:])
        return held

    def _write_pair(self, pair: yzaim.Pair, low: int, high: int) -> None:
        self._latched_high.pop(pair.low, None)
        if not self._ram["modbus_enable"]:
            self.refused_writes += 1
            return
        value = yzaim.join32(low, high)
        if pair is _CACHE:
            self._store_cache(value)
            return
        if pair is _INC:
            self._ram[yzaim.BY_ADDRESS[pair.low].name] = low
            self._ram[yzaim.BY_ADDRESS[pair.high].name] = high
            if value == 0 and self._ram["gear_numerator"] == 0:
                self.emergency_stop()
            elif not self._speed_mode:
                self._move_to(self.target + value)
            return
        if value == 0 and self._ram["gear_numerator"] == 0:
            self.clear_position()
        elif not self._speed_mode:
            self._move_to(value)

    def _write_register(self, reg: yzaim.Register, word: int) -> None:
        value = reg.from_word(word)
        allowed = self._ram["modbus_enable"] or reg.name == "modbus_enable"
        if not (allowed and reg.writable and reg.valid(value)):
            self.refused_writes += 1
            return
        name = reg.name
        if name == "save_flag":
            self._save(value)
            self._save_reply = word
            return
        if name == "sync_control":
            self._take_queued_cache()
        self._ram[name] = value
        if name == "output_enable":
            self._set_output(bool(value))
        elif name in _GAIN_REGISTERS:
            self._apply_gains()
        elif name in _PROFILE_REGISTERS:
            self._apply_profile()
            if self._speed_mode:
                self._run_speed()
        elif name == "dir_polarity" and self._speed_mode:
            self._run_speed()
        elif name == "special_function":
            self._apply_mode()
        elif name in ("standstill_max_output", "max_current"):
            self._apply_limits()
        elif name == "sync_control":
            self._sync_signal()

    # ---------------------------------------------------------------- functions
    def emergency_stop(self) -> None:
        """EasyCan 0x10 (5.3d): stop at once; the position loop brakes (4.7). Always works."""
        if self._speed_mode:
            self._ram["special_function"] = 0
            self._speed_mode = False
        self.drive.halt()

    def clear_position(self) -> bool:
        """EasyCan 0x11 (5.3e) / 0 to 0x16 at gear 0 (4.7): the position here becomes 0."""
        if not self._ram["modbus_enable"]:
            return False
        self._offset -= self.position
        return True

    def write_position_cache(self, position: int, *, at: float | None = None,
                             batch: Hashable | None = None) -> int:
        """A position-cache frame (5.3c): store ``position``; returns the current position.

        MotorRefused(TOO_FAST) when the previous cache value was not taken yet. ``at`` as for
        :meth:`write_words`; ``batch``: a key shared by frames the simulator received
        together, whose order is known but not when each reached the bus (module doc)."""
        if not yzaim.INT32_MIN <= position <= yzaim.INT32_MAX:
            raise ValueError(f"cache position {position} is not a signed 32-bit value")
        self._at = self.time if at is None else min(at, self.time)
        if not self._ram["modbus_enable"]:
            self.refused_writes += 1
            return self.position
        together = batch is not None and batch == self._cache_batch
        if self._cache_queue or (together and self._sync_internal()
                                 and self._cache_is_pending()):
            if len(self._cache_queue) >= MAX_QUEUED_CACHE:
                self._refuse_cache()
            self._cache_queue.append(position)
        else:
            if self._cache_is_pending():
                self._refuse_cache()
            self._store_cache(position)
        self._cache_batch = batch
        return self.position

    def dir_edge(self) -> None:
        """A DIR input edge: with 0x1C = 255 the motors take their caches now (5.2 0x1B)."""
        if self._ram["sync_control"] == yzaim.SYNC_BY_DIR_SIGNAL:
            self._take_cache()

    # ---------------------------------------------------------------- world (simulator)
    def set_load(self, *, inertia: float | None = None, friction: float | None = None) -> None:
        self.drive.set_load(inertia=inertia, friction=friction)

    def set_blocked(self, blocked: bool) -> None:
        self.drive.set_blocked(blocked)

    def set_disturbance(self, torque_nm: float) -> None:
        self.drive.set_disturbance(torque_nm)

    def set_supply_voltage(self, volts: float) -> None:
        self.supply_v = float(volts)
        self._check_supply()

    def world(self) -> dict[str, float | bool]:
        """The world around the motor as the simulator set it (control channel ``state``)."""
        return {**self.drive.world(), "supply_v": self.supply_v, "battery_ok": self.battery_ok}

    def set_battery(self, ok: bool) -> None:
        """Multi-turn backup battery present and charged (False: warning 0x13)."""
        self.battery_ok = bool(ok)
        self._check_supply()

    # ---------------------------------------------------------------- time
    def advance(self, seconds: float) -> None:
        self.advance_to(self.time + seconds)

    def advance_to(self, t: float) -> None:
        """Run the motor up to simulated time ``t``: the 2 ms duties, then the physics."""
        while self._next_tick <= t:
            tick = self._next_tick
            self.drive.advance_to(tick)
            self._tick()
            self._next_tick = tick + TICK_S
        self.drive.advance_to(t)

    def _tick(self) -> None:
        if self._sync_internal():
            if self._cache_queue and not self._cache_pending:
                self._set_cache(self._cache_queue.popleft())
            if self._cache_pending:
                self._take_cache()
        current = self.current_a
        self._i2 += (current * current - self._i2) * (TICK_S / THERMAL_TAU_S)
        standstill = abs(self.speed_rpm) < STANDSTILL_RPM
        if standstill != self._standstill:
            self._standstill = standstill
            self._apply_limits()
        if not self.enabled:
            self._stall_t = self._over_t = 0.0
            return
        max_a, still_a = self._limits_a()
        stall_s = yzaim.stall_alarm_seconds(self._ram["standstill_max_output"])
        over_s = yzaim.over_current_alarm_seconds(self._ram["max_current"])
        on_still = standstill and abs(current) >= SATURATED * min(max_a, still_a)
        self._stall_t = self._stall_t + TICK_S if on_still else 0.0
        on_max = abs(current) >= SATURATED * max_a
        self._over_t = self._over_t + TICK_S if on_max else 0.0
        if stall_s is not None and self._stall_t >= stall_s - 1e-9:
            self._trip(_ALARM["stall"])
        elif over_s is not None and self._over_t >= over_s - 1e-9:
            self._trip(_ALARM["over_current"])

    # ---------------------------------------------------------------- internals
    def _limits_a(self) -> tuple[float, float]:
        """(current limit in motion, current limit at standstill), amperes."""
        ram = self._ram
        max_a = min(ram["max_current"] / _R["max_current"].per_unit, self.peak_a)
        still = ram["standstill_max_output"] / _R["standstill_max_output"].per_unit / 100
        return max_a, still * self.peak_a

    def _apply_limits(self) -> None:
        max_a, still_a = self._limits_a()
        limit = min(max_a, still_a) if self._standstill else max_a
        param = phys.torque_limit_param(limit, self.peak_a)
        if param != self._torque_param:
            self._torque_param = param
            self.drive.set_loop(*self.drive.loop[:4], param / phys.ENGINE_PARAM_MAX)

    def _apply_gains(self) -> None:
        r = self._ram
        loop = phys.loop_coefficients(r["position_loop_kp"], r["speed_loop_kp"],
                                      r["speed_loop_integration_time"])
        self.drive.set_loop(*loop, self.drive.loop[4])

    def _apply_profile(self) -> None:
        speed, accel = phys.profile(self._ram["target_speed"], self._ram["acceleration"],
                                    self.model.max_rpm)
        self.drive.set_profile(speed, accel)

    def _apply_mode(self) -> None:
        speed_mode = self._ram["special_function"] == yzaim.SpecialFunction.SPEED_MODE
        if speed_mode:
            self._speed_mode = True
            self._run_speed()
        elif self._speed_mode:
            self._speed_mode = False
            self.drive.run_speed(0)

    def _speed_limit_rpm(self) -> int:
        return min(self._ram["target_speed"], self.model.max_rpm)

    def _run_speed(self) -> None:
        rpm = self._speed_limit_rpm()
        self.drive.run_speed(-rpm if self._ram["dir_polarity"] else rpm)

    def _move_to(self, position: int) -> None:
        core = (position - self._offset) * phys.CORE_PER_COUNT
        self.drive.move_to_counts(core)

    def _set_output(self, on: bool) -> None:
        if not on:
            self._alarm = 0 if yzaim.alarm(self._alarm).stops_motor else self._alarm
            self.drive.disable()
            return
        if yzaim.alarm(self._alarm).stops_motor:
            self._ram["output_enable"] = 0
            self.refused_writes += 1
            return
        self.drive.enable()
        if self._speed_mode:
            self._run_speed()

    def _trip(self, found: yzaim.Alarm) -> None:
        if yzaim.alarm(self._alarm).stops_motor and self._alarm:
            return
        self._alarm = found.code
        if found.stops_motor:
            self.drive.disable()

    def _check_supply(self) -> None:
        if self.supply_v > self.model.supply_v[1] * OVER_VOLTAGE_MARGIN:
            self._trip(_ALARM["over_voltage"])
        elif self._alarm in (0, _ALARM["battery_warning"].code):
            warn = self.model.multi_turn and not self.battery_ok
            self._alarm = _ALARM["battery_warning"].code if warn else 0

    def _save(self, value: int) -> None:
        if value in (yzaim.SaveFlag.SAVE, yzaim.SaveFlag.SAVE_SINGLE_TURN_ORIGIN):
            self.store.save_registers(self._ram)
            if value == yzaim.SaveFlag.SAVE_SINGLE_TURN_ORIGIN:
                self.store.record_position(self.position)
            self._save_flag = yzaim.SaveFlag.SAVED
        else:
            self._save_flag = yzaim.SaveFlag(value)

    # ---- synchronous cache
    def _sync_internal(self) -> bool:
        sync = self._ram["sync_control"]
        return sync != 0 and sync != yzaim.SYNC_BY_DIR_SIGNAL

    def _cache_is_pending(self) -> bool:
        """Is a cache value waiting, as of the arrival of the frame being executed? A value
        already taken at the tick after it arrived still counts for a frame that arrived
        before that tick (handled late): frames are judged by when they reached the bus."""
        if self._ram["sync_control"] == 0:
            return False
        return self._cache_pending or self._at < self._cache_due

    def _refuse_cache(self) -> None:
        self.refused_cache += 1
        raise MotorRefused(Refusal.TOO_FAST,
                           "position cache written twice within one 2 ms cycle")

    def _set_cache(self, position: int) -> None:
        low, high = yzaim.split32(position)
        self._ram["position_cache_low"], self._ram["position_cache_high"] = low, high
        self._cache_pending = True

    def _take_queued_cache(self) -> None:
        """Take the pending value and every queued one at once, in order (a 0x1C write
        came after them on the bus, so each had its cycle before it)."""
        if not self._cache_queue:
            return
        while self._cache_queue:
            if self._cache_pending:
                self._take_cache()
            self._set_cache(self._cache_queue.popleft())
        self._take_cache()

    def _store_cache(self, position: int) -> None:
        self._set_cache(position)
        if not self._sync_internal():
            self._cache_due = -math.inf  # waits for a signal or a DIR edge (pending flag)
            return
        due = self._next_tick - math.floor((self._next_tick - self._at) / TICK_S) * TICK_S
        self._cache_due = due if due > self._at else due + TICK_S  # the first tick after
        if self._at < self._next_tick - TICK_S:
            self._take_cache()  # handled late: the tick that takes it has already run

    def _cache(self) -> int:
        return yzaim.join32(self._ram["position_cache_low"], self._ram["position_cache_high"])

    def _take_cache(self) -> None:
        self._cache_pending = False
        if self._speed_mode:
            return
        if yzaim.uses_internal_profile(self._ram["acceleration"]):
            self._move_to(self._cache())  # 5.4c: the drive's curve, it may lag behind
            return
        # 5.4d: no curve: interpolate to the cache within the cycle, at most at the speed limit
        most = self._speed_limit_rpm() / 60.0 * yzaim.COUNTS_PER_REV * TICK_S
        step = max(-most, min(most, self._cache() - self.target))
        self.drive.follow_counts(step * phys.CORE_PER_COUNT, TICK_S)

    def _sync_signal(self) -> None:
        """0x1C written: > 0 restarts the 2 ms time base here and takes a pending cache."""
        if self._sync_internal():
            if self._cache_pending:
                self._take_cache()
            self._cache_due = self._at
            self._next_tick = self._at + TICK_S

    # ---------------------------------------------------------------- 4 kHz trace
    # What servobus.sim.core.capture records of this motor (trace_buffer() on sim://easycan and
    # sim://modbus): its address, its counts and offset, its alarm - not its core drive's.
    counts_per_rev = yzaim.COUNTS_PER_REV

    @property
    def trace_id(self) -> int:
        return self.address

    def trace_sample(self) -> tuple[float, float, float, float, int]:
        """Position, following error (counts), speed, current, status bits; the status bits
        as the Axis reads them (servobus.families.yzaim.family.axis_status)."""
        drive = self.drive
        position = drive.position / phys.CORE_PER_COUNT + self._offset
        speed = drive.speed_rpm
        near = abs(self.target - position) <= yzaim.POSITION_TOLERANCE_COUNTS
        moving, in_position = motion_state(not near, near, speed)  # as AxisStatus has them
        stops = self._alarm != 0 and self.alarm.stops_motor
        return (position, drive.position_error / phys.CORE_PER_COUNT, speed, drive.current_a,
                status_bits(self._ram["output_enable"] == 1 and not stops, moving,
                            in_position, self._alarm != 0))


_ALARM = yzaim.ALARM_BY_NAME


def address_in_pair(address: int, pair: yzaim.Pair) -> bool:
    return address in (pair.low, pair.high)


def _pair_word(value: int, index: int) -> int:
    return yzaim.split32(value)[index]


def _clip(reg: yzaim.Register, value: float) -> int:
    return max(reg.minimum, min(reg.maximum, round(value)))
