"""YZ-AIM integrated DC servo motors: the register map and the device family.

Source: the YZ-AIM "EasyCan v3.5" manual (a machine translation); section numbers below
are that manual's (1 features and model tables, 2.3 alarms, 3.2 electronic gear,
4.1-4.10 parameter tuning and special functions, 5.2 register table, 5.3 frame formats,
5.4 host control process). See docs/easycan.md and docs/modbus.md.

ONE table, :data:`REGISTERS`, holds every register 0x00-0x1D: name, access, raw range,
unit and scale, EEPROM storage, default. Both wires serve the same 16-bit registers
(EasyCan little-endian, Modbus RTU big-endian); 32-bit values are two registers with
the LOW word at the LOWER address (:data:`PAIRS`).

Decisions where the manual disagrees with itself or is silent (each also noted at the
entry it concerns):

* Low/high words: the register table (5.2) calls 0x0C "lower 16 bits" but describes it
  as the higher ones (likewise 0x16/0x17); the frame examples of 5.4 (00 80 00 00 =
  32768 written at 0x0C) are authoritative: low word at the lower address.
* The rows 0x0E-0x13 are garbled in the text. Read as: 0x0E alarm code, 0x0F system
  current (x / 2000 A, 0..32767), 0x10 motor speed (x / 10 rpm, -30000..30000), 0x11
  supply voltage (x / 327 V; 327 is also the "1 V" of 0x08), 0x12 drive temperature
  (degrees C, signed, scale 1 - the manual gives no scale), 0x13 output PWM (signed
  duty, 32767 = 100 % - the manual gives no scale).
* 0x14 save flag: the table says 0~1 but lists 0 not saved / 1 save / 2 saved, and 4.10
  writes 3 (save the single-turn origin, reads back 2): range 0..3.
* 0x15 device address: listed read-only, yet "the new address takes effect after saving
  and power-on" and the PC software sets it: read-write, stored by the save flag. The
  table's 0~255 is narrowed to 1..254: 0xFF is the host's own address on EasyCan and 0
  is the Modbus broadcast address.
* 0x19 special function: the table says 0~100 but its own text uses 10~32768 (power-on
  angle); range 0..32768 without 5, which no section defines.
* 0x1A/0x1B position cache: the table gives -32768~32767 per register; each register is
  one 16-bit word and the pair is one signed 32-bit position, like 0x16/0x17.
* Units digits: 0x05 (pulse polarity), 0x07 (alarm output contact), 0x18 (stall alarm
  time) and 0x1D (over-current alarm time) give the units digit a second meaning on top
  of the value (5.2). The value keeps its full scale (609 = 60.9 %, 10009 = 10.009 A).
  A units digit of 0 in 0x18 means no stall alarm (stated for 0x1D, applied to both);
  the stall time's unit is not stated: seconds, as in 0x1D.
* Acceleration 0x03: the table says "greater than 60000" disables the drive's curve,
  4.1 says "greater than or equal to 60,000", and 5.4c/d use 60000 as the no-curve value:
  >= 60000 disables it.
* Alarm codes: the manual names only 0x14 (stall, "one long and four short flashes").
  Read the flash pattern as the code's two hex digits (long = high digit, short = low
  digit). Over-current 0x11, over-voltage 0x12 and battery warning 0x13 are servobus
  codes for the protections the manual lists (1 features, 5.2 0x1D, 4.9) but does not
  number.
* Defaults are servobus choices (the manual gives no factory table) except the gear
  (3.2: 8192 pulses per revolution by default, 32768:8192 reduced to 4:1) and the speed
  and acceleration of the 5.4 examples (1000 rpm, 10000 rpm/s).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum
from math import gcd

from servobus.errors import ArgumentRangeError

FAMILY = "yzaim"
COUNTS_PER_REV = 32_768  # 15-bit absolute encoder (1 features)
REGISTER_COUNT = 0x1E  # addresses 0x00..0x1D
WORD_MAX = 0xFFFF
INT32_MIN = -(1 << 31)
INT32_MAX = (1 << 31) - 1
NO_PROFILE_ACCEL = 60_000  # 0x03 >= this: no internal acceleration curve (4.1)
SYNC_CYCLE_S = 0.002  # position-cache interpolation period (5.2 0x1A, 5.4c)
SYNC_BY_DIR_SIGNAL = 255  # 0x1C value: trigger synchronisation on the DIR input
SPEED_MODE_DUTY_PERCENT = (10.0, 90.0)  # special function 3: duty range ...
SPEED_MODE_MAX_RPM = 1000.0  # ... mapped linearly onto 0..1000 rpm
MECHANICAL_ORIGIN_OFFSET_DEG = 36.0  # special function 1: stall, then forward 36 deg
POSITION_TOLERANCE_COUNTS = 10  # 5.4a: "allow +-10 error" when comparing positions
MAX_PULSE_FREQUENCY_HZ = 500_000  # pulse input (1 model tables)
PULSE_SAMPLING_HZ = 2_000


class Access(Enum):
    R = "R"  # read-only: the drive's measurement or state
    W = "W"  # write-only (no YZ-AIM register is; kept for the protocol tables)
    RW = "RW"  # setting: reads back what was written
    ACTION = "action"  # a write starts something (a move, a save); a read returns state


@dataclass(frozen=True)
class Register:
    """One 16-bit register. Ranges are in raw register units (signed where ``signed``)."""

    address: int
    name: str  # snake_case: CLI, JSON backups, Axis API
    access: Access
    minimum: int
    maximum: int
    unit: str  # engineering unit after dividing by ``per_unit``
    per_unit: float  # raw counts per engineering unit (2000 per A, 10 per rpm, ...)
    saved: bool  # written to EEPROM when the save flag 0x14 is set
    default: int | None  # power-on value of the virtual motor; None for measurements
    doc: str
    invalid: tuple[int, ...] = ()  # values inside minimum..maximum the drive does not define

    @property
    def signed(self) -> bool:
        """The 16-bit word is two's complement."""
        return self.minimum < 0

    @property
    def writable(self) -> bool:
        return self.access is not Access.R

    def valid(self, raw: int) -> bool:
        return self.minimum <= raw <= self.maximum and raw not in self.invalid

    def check(self, raw: int) -> int:
        """Return ``raw`` if the drive accepts it, else raise ArgumentRangeError."""
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise ArgumentRangeError(f"{self.name} must be an integer, got {raw!r}")
        if not self.valid(raw):
            gaps = f" except {', '.join(map(str, self.invalid))}" if self.invalid else ""
            raise ArgumentRangeError(
                f"{self.name} (0x{self.address:02X}) = {raw} is outside "
                f"{self.minimum}..{self.maximum}{gaps} ({self._unit_text()})"
            )
        return raw

    def check_write(self, raw: int) -> int:
        """Range check plus access: writing a read-only register is refused."""
        if not self.writable:
            raise ArgumentRangeError(f"{self.name} (0x{self.address:02X}) is read-only")
        return self.check(raw)

    def word(self, raw: int) -> int:
        """The 16-bit wire word of a raw value (two's complement when signed)."""
        if not -0x8000 <= raw <= WORD_MAX:
            raise ArgumentRangeError(f"{self.name} = {raw} does not fit a 16-bit register")
        return raw & WORD_MAX

    def from_word(self, word: int) -> int:
        """Raw value of a 16-bit wire word (sign applied when the register is signed)."""
        if not 0 <= word <= WORD_MAX:
            raise ArgumentRangeError(f"register word {word} is outside 0..{WORD_MAX}")
        return to_signed16(word) if self.signed else word

    def to_engineering(self, raw: int) -> float:
        return raw / self.per_unit

    def from_engineering(self, value: float) -> int:
        """Raw value nearest to ``value`` in engineering units, range-checked."""
        return self.check(round(value * self.per_unit))

    def _unit_text(self) -> str:
        if self.per_unit == 1:
            return self.unit
        return f"raw; {self.per_unit:g} per {self.unit}"


_R, _W, _RW, _ACT = Access.R, Access.W, Access.RW, Access.ACTION


def _reg(address: int, name: str, access: Access, lo: int, hi: int, unit: str,
         per_unit: float, saved: bool, default: int | None, doc: str,
         invalid: tuple[int, ...] = ()) -> Register:
    return Register(address, name, access, lo, hi, unit, per_unit, saved, default, doc, invalid)


_WORD = (0, WORD_MAX)

#: THE YZ-AIM register table (manual 5.2, corrected as the module docstring says).
REGISTERS: tuple[Register, ...] = (
    _reg(0x00, "modbus_enable", _RW, 0, 1, "-", 1, False, 0,
         "1: the host controls the motor over CAN/Modbus; 0: pulse/direction inputs do. "
         "Powers up as 1 when gear numerator 0 is saved (4.8)"),
    _reg(0x01, "output_enable", _RW, 0, 1, "-", 1, False, 1,
         "1: motor energised; 0: driver output off (motor free)"),
    _reg(0x02, "target_speed", _RW, 0, 3000, "rpm", 1, True, 1000,
         "speed in speed mode; cruise speed of position moves; speed limit of the "
         "cycle-synchronous mode (5.4c)"),
    _reg(0x03, "acceleration", _RW, 0, 65535, "rpm/s", 1, True, 10000,
         "below 60000 the drive generates its own acceleration/deceleration curve; "
         ">= 60000: none, the motor follows the commanded steps (4.1)"),
    _reg(0x04, "field_weakening_angle", _RW, 0, 306, "-", 1, True, 0,
         "internal, the manual says not to set it (its unit 'r/min' is a translation "
         "artefact)"),
    _reg(0x05, "speed_loop_kp", _RW, 0, 10000, "-", 1000, True, 1000,
         "speed loop gain 0.0..10.0, larger = stiffer; units digit even: pulse input "
         "polarity valid at turn-off, odd: at turn-on"),
    _reg(0x06, "speed_loop_integration_time", _RW, 2, 2000, "ms", 1, True, 20,
         "speed loop integration time, smaller = stiffer; 2000 cancels integration (4.4)"),
    _reg(0x07, "position_loop_kp", _RW, 60, 30000, "-", 1, True, 1500,
         "position loop gain, larger = stiffer; units digit even: alarm output normally "
         "open, odd: normally closed"),
    _reg(0x08, "speed_feedforward", _RW, 0, 3924, "V/krpm", 327, True, 327,
         "0..12.0 V/krpm, 327 = 1 V/krpm; no need to set"),
    _reg(0x09, "dir_polarity", _RW, 0, 1, "-", 1, True, 0,
         "0: DIR input not conducting = clockwise; 1: conducting = clockwise"),
    _reg(0x0A, "gear_numerator", _RW, 0, 65535, "-", 1, True, 4,
         "electronic gear numerator (encoder counts per gear_denominator pulses); 0 "
         "selects communication specials: writing 0 to absolute_position clears it, 0 to "
         "incremental_position stops, and modbus_enable powers up as 1 (4.7, 4.8)"),
    _reg(0x0B, "gear_denominator", _RW, 1, 65535, "-", 1, True, 1,
         "electronic gear denominator (3.2: 8192 pulses/rev = 32768:8192 = 4:1)"),
    _reg(0x0C, "incremental_position_low", _ACT, *_WORD, "counts", 1, False, 0,
         "low word of the relative move (32-bit with 0x0D); writing moves by it; "
         "the write reply carries the current absolute position"),
    _reg(0x0D, "incremental_position_high", _ACT, *_WORD, "counts", 1, False, 0,
         "high word of the relative move"),
    _reg(0x0E, "alarm_code", _R, *_WORD, "-", 1, False, None,
         "0 = no alarm; see ALARMS (2.3: 0x14 stall)"),
    _reg(0x0F, "system_current", _R, 0, 32767, "A", 2000, False, None,
         "supply current, x / 2000 A"),
    _reg(0x10, "motor_speed", _R, -30000, 30000, "rpm", 10, False, None,
         "actual speed, x / 10 rpm, signed"),
    _reg(0x11, "supply_voltage", _R, 0, 32767, "V", 327, False, None,
         "supply voltage, x / 327 V"),
    _reg(0x12, "drive_temperature", _R, -32768, 32767, "degC", 1, False, None,
         "drive temperature, degrees C (motor limit 85 degC, 1 model tables)"),
    _reg(0x13, "output_pwm", _R, -32767, 32767, "%", 327.67, False, None,
         "signed output duty, 32767 = 100 %"),
    _reg(0x14, "save_flag", _ACT, 0, 3, "-", 1, False, 0,
         "write 1: save the saved registers to EEPROM (reads 1 while saving, 2 when "
         "saved); write 3: also save the single-turn origin (4.10); 0: not saved"),
    _reg(0x15, "device_address", _RW, 1, 254, "-", 1, True, 1,
         "CAN identifier / Modbus slave address; takes effect after save and power-on"),
    _reg(0x16, "absolute_position_low", _ACT, *_WORD, "counts", 1, False, 0,
         "low word of the absolute position (32-bit with 0x17); writing moves there "
         "(0 clears it when gear_numerator is 0); the write reply carries the current "
         "absolute position"),
    _reg(0x17, "absolute_position_high", _ACT, *_WORD, "counts", 1, False, 0,
         "high word of the absolute position"),
    _reg(0x18, "standstill_max_output", _RW, 0, 609, "%", 10, True, 303,
         "maximum output at standstill 0..60.9 %; units digit 1..9: stall alarm after "
         "that many seconds, 0: no stall alarm"),
    _reg(0x19, "special_function", _RW, 0, 32768, "-", 1, True, 0,
         "operating mode, see SpecialFunction; 10..32768: turn to x * 360 / 32768 deg "
         "after power-on", invalid=(5,)),
    _reg(0x1A, "position_cache_low", _RW, *_WORD, "counts", 1, False, 0,
         "low word of the synchronous position cache (32-bit with 0x1B); read every 2 ms "
         "in synchronous mode"),
    _reg(0x1B, "position_cache_high", _RW, *_WORD, "counts", 1, False, 0,
         "high word of the synchronous position cache"),
    _reg(0x1C, "sync_control", _RW, 0, 65535, "-", 1, False, 0,
         "0: synchronous mode off; > 0: on, cache taken on the internal 2 ms time base; "
         "255: taken on the DIR signal"),
    _reg(0x1D, "max_current", _RW, 0, 10009, "A", 1000, True, 5000,
         "maximum working current 0..10.009 A (raw mA); units digit 1..9: alarm and stop "
         "after that many seconds at the limit, 0: hold the limit without alarm"),
)

BY_ADDRESS: dict[int, Register] = {r.address: r for r in REGISTERS}
BY_NAME: dict[str, Register] = {r.name: r for r in REGISTERS}
SAVED: tuple[Register, ...] = tuple(r for r in REGISTERS if r.saved)


@dataclass(frozen=True)
class Pair:
    """A signed 32-bit value in two registers, low word at the lower address."""

    name: str
    low: int  # address of the low word; the high word is at low + 1
    doc: str
    minimum: int = INT32_MIN
    maximum: int = INT32_MAX
    unit: str = "counts"

    @property
    def high(self) -> int:
        return self.low + 1

    def check(self, value: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ArgumentRangeError(f"{self.name} must be an integer, got {value!r}")
        if not self.minimum <= value <= self.maximum:
            raise ArgumentRangeError(
                f"{self.name} (0x{self.low:02X}/0x{self.high:02X}) = {value} is outside "
                f"{self.minimum}..{self.maximum} ({self.unit})"
            )
        return value


PAIRS: tuple[Pair, ...] = (
    Pair("incremental_position", 0x0C, "relative move, encoder counts (32768 per rev)"),
    Pair("absolute_position", 0x16, "absolute position, encoder counts (32768 per rev)"),
    Pair("position_cache", 0x1A, "synchronous position cache, encoder counts"),
)
PAIR_BY_NAME: dict[str, Pair] = {p.name: p for p in PAIRS}
PAIR_BY_LOW: dict[int, Pair] = {p.low: p for p in PAIRS}


# ------------------------------------------------------------------ lookup
def register(key: str | int) -> Register:
    """A register by snake_case name or address; unknown keys raise ArgumentRangeError."""
    found = BY_NAME.get(key) if isinstance(key, str) else BY_ADDRESS.get(key)
    if found is None:
        what = repr(key) if isinstance(key, str) else f"0x{key:02X}"
        raise ArgumentRangeError(
            f"unknown YZ-AIM register {what}; registers are 0x00..0x{REGISTER_COUNT - 1:02X}"
        )
    return found


def parameter(name: str) -> Register | Pair:
    """A single register or a 32-bit pair by name (what ``servobus set NAME`` accepts)."""
    if name in PAIR_BY_NAME:
        return PAIR_BY_NAME[name]
    if name in BY_NAME:
        return BY_NAME[name]
    known = ", ".join([*BY_NAME, *PAIR_BY_NAME])
    raise ArgumentRangeError(f"unknown YZ-AIM parameter {name!r}; known: {known}")


def encode_parameter(name: str, value: int) -> tuple[int, tuple[int, ...]]:
    """(start address, wire words) for writing ``value``; range and access checked."""
    p = parameter(name)
    if isinstance(p, Pair):
        return p.low, split32(p.check(value))
    return p.address, (p.word(p.check_write(value)),)


def decode_parameter(name: str, words: tuple[int, ...]) -> int:
    """The value of a parameter from the wire words read at its address."""
    p = parameter(name)
    if isinstance(p, Pair):
        if len(words) != 2:
            raise ArgumentRangeError(f"{name} needs 2 register words, got {len(words)}")
        return join32(words[0], words[1])
    if len(words) != 1:
        raise ArgumentRangeError(f"{name} needs 1 register word, got {len(words)}")
    return p.from_word(words[0])


def defaults() -> dict[str, int]:
    """Power-on values of the registers that have one."""
    return {r.name: r.default for r in REGISTERS if r.default is not None}


# ------------------------------------------------------------------ numbers
def to_signed16(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word


def split32(value: int) -> tuple[int, int]:
    """(low word, high word) of a signed or unsigned 32-bit value."""
    if not INT32_MIN <= value <= 0xFFFF_FFFF:
        raise ArgumentRangeError(f"{value} does not fit in 32 bits")
    value &= 0xFFFF_FFFF
    return value & WORD_MAX, value >> 16


def join32(low: int, high: int) -> int:
    """Signed 32-bit value from its low and high words."""
    if not (0 <= low <= WORD_MAX and 0 <= high <= WORD_MAX):
        raise ArgumentRangeError(f"register words {low}, {high} are outside 0..{WORD_MAX}")
    value = (high << 16) | low
    return value - (1 << 32) if value & 0x8000_0000 else value


# ------------------------------------------------------------------ units digits
def units_digit(raw: int) -> int:
    return abs(raw) % 10


def pulse_polarity_at_turn_on(speed_loop_kp: int) -> bool:
    """0x05 units digit odd: the pulse input is valid when it turns on (else at turn-off)."""
    return units_digit(speed_loop_kp) % 2 == 1


def alarm_output_normally_closed(position_loop_kp: int) -> bool:
    """0x07 units digit odd: the alarm output is normally closed (opens on alarm)."""
    return units_digit(position_loop_kp) % 2 == 1


def stall_alarm_seconds(standstill_max_output: int) -> int | None:
    """0x18 units digit: seconds at the standstill limit before the stall alarm; None: never."""
    return units_digit(standstill_max_output) or None


def over_current_alarm_seconds(max_current: int) -> int | None:
    """0x1D units digit: seconds at the current limit before alarm and stop; None: hold."""
    return units_digit(max_current) or None


def uses_internal_profile(acceleration: int) -> bool:
    """0x03 below 60000: the drive generates its own acceleration curve (4.1)."""
    return acceleration < NO_PROFILE_ACCEL


# ------------------------------------------------------------------ special functions
class SpecialFunction(IntEnum):
    """Register 0x19 (5.2; 3.3, 4.5-4.10). Values 10..32768 are a power-on angle."""

    PULSE_DIRECTION = 0
    FIND_MECHANICAL_ORIGIN = 1
    ENCODER_FOLLOW = 2
    SPEED_MODE = 3
    FIND_MECHANICAL_ORIGIN_TO_ENCODER_ZERO = 4
    BATTERY_RETURN_TO_ZERO = 6
    BRAKE_MULTI_TURN = 7
    BRAKE_MULTI_TURN_RETURN_TO_ORIGIN = 8
    COMMUNICATION_INTERPOLATION = 9


POWER_ON_ANGLE_MIN = 10  # 0x19 values from here on: turn to this angle after power-on
POWER_ON_ANGLE_MAX = COUNTS_PER_REV

SPECIAL_FUNCTION_TEXTS: dict[SpecialFunction, str] = {
    SpecialFunction.PULSE_DIRECTION: "pulse + direction position mode",
    SpecialFunction.FIND_MECHANICAL_ORIGIN:
        "after power-on reverse to the mechanical stop, then forward 36 deg as origin",
    SpecialFunction.ENCODER_FOLLOW: "encoder follow mode (quadrature A/B input)",
    SpecialFunction.SPEED_MODE: "speed mode, PWM duty 10..90 % = 0..1000 rpm",
    SpecialFunction.FIND_MECHANICAL_ORIGIN_TO_ENCODER_ZERO:
        "after power-on find the mechanical origin, then forward to the encoder zero",
    SpecialFunction.BATTERY_RETURN_TO_ZERO:
        "with battery: return to zero after power-on",
    SpecialFunction.BRAKE_MULTI_TURN:
        "brake motor: multi-turn position restored into absolute_position at power-on",
    SpecialFunction.BRAKE_MULTI_TURN_RETURN_TO_ORIGIN:
        "brake motor: multi-turn position restored, return to the origin at power-on",
    SpecialFunction.COMMUNICATION_INTERPOLATION:
        "communication interpolation without lag (10 kHz 50 % clock on PU)",
}


def special_function_text(value: int) -> str:
    """What register 0x19 = ``value`` selects."""
    try:
        return SPECIAL_FUNCTION_TEXTS[SpecialFunction(value)]
    except ValueError:
        pass
    if POWER_ON_ANGLE_MIN <= value <= POWER_ON_ANGLE_MAX:
        return f"turn to {power_on_angle_deg(value):.2f} deg after power-on"
    return f"undefined special function {value}"


def power_on_angle_deg(value: int) -> float:
    """Special function 10..32768: the angle x * 360 / 32768 (4.5)."""
    return value * 360.0 / COUNTS_PER_REV


def speed_mode_rpm(duty_percent: float) -> float:
    """Special function 3: PWM duty 10..90 % maps onto 0..1000 rpm, clamped."""
    lo, hi = SPEED_MODE_DUTY_PERCENT
    frac = min(max((duty_percent - lo) / (hi - lo), 0.0), 1.0)
    return frac * SPEED_MODE_MAX_RPM


class SaveFlag(IntEnum):
    """Register 0x14 (5.2, 4.10)."""

    NOT_SAVED = 0
    SAVE = 1  # write to save; reads 1 while saving
    SAVED = 2
    SAVE_SINGLE_TURN_ORIGIN = 3  # 4.10: also saves the single-turn origin; reads 2 after


# ------------------------------------------------------------------ gear and motion
def gear_for_pulses_per_rev(pulses: int) -> tuple[int, int]:
    """(numerator, denominator) for ``pulses`` input pulses per revolution (3.2)."""
    if not 1 <= pulses <= WORD_MAX:
        raise ArgumentRangeError(f"pulses per revolution {pulses} is outside 1..{WORD_MAX}")
    g = gcd(COUNTS_PER_REV, pulses)
    return COUNTS_PER_REV // g, pulses // g


def pulses_per_rev(numerator: int, denominator: int) -> float:
    """Input pulses for one revolution: 32768 x denominator / numerator."""
    if numerator == 0:
        raise ArgumentRangeError("gear_numerator 0 selects communication mode: no pulse gear")
    return COUNTS_PER_REV * denominator / numerator


def pulses_to_counts(pulses: float, numerator: int, denominator: int) -> float:
    return pulses * numerator / denominator


def pulse_frequency_hz(rpm: float, pulses_per_revolution: float) -> float:
    """Pulse frequency for a speed: rpm / 60 x pulses per revolution (3.2)."""
    return rpm / 60.0 * pulses_per_revolution


def counts_per_cycle(rpm: float, cycle_s: float = SYNC_CYCLE_S) -> float:
    """Counts to add to the cache each cycle for ``rpm`` (5.4c: 600 rpm = 655.36 / 2 ms)."""
    return rpm / 60.0 * cycle_s * COUNTS_PER_REV


def counts_to_deg(counts: float) -> float:
    return counts * 360.0 / COUNTS_PER_REV


def deg_to_counts(deg: float) -> float:
    return deg * COUNTS_PER_REV / 360.0


# ------------------------------------------------------------------ alarms
@dataclass(frozen=True)
class Alarm:
    code: int
    name: str
    text: str
    stops_motor: bool  # an alarm stops and frees the motor; a warning does not

    @property
    def flashes(self) -> tuple[int, int]:
        """(long, short) red LED flashes: the code's hex digits (2.3: 0x14 = 1 long 4 short)."""
        return self.code >> 4, self.code & 0x0F


#: Register 0x0E. Only 0x14 is numbered by the manual (2.3); see the module docstring.
ALARMS: tuple[Alarm, ...] = (
    Alarm(0x00, "none", "normal operation", False),
    Alarm(0x11, "over_current",
          "over-current: max_current held longer than its units digit allows", True),
    Alarm(0x12, "over_voltage", "over-voltage on the supply", True),
    Alarm(0x13, "battery_warning",
          "multi-turn battery low: the position may be lost at power-off", False),
    Alarm(0x14, "stall",
          "stall: standstill_max_output held longer than its units digit allows", True),
)
ALARM_BY_CODE: dict[int, Alarm] = {a.code: a for a in ALARMS}
ALARM_BY_NAME: dict[str, Alarm] = {a.name: a for a in ALARMS}


def alarm(code: int) -> Alarm:
    """The alarm for register 0x0E's value; unknown codes are an alarm named ``unknown``."""
    found = ALARM_BY_CODE.get(code)
    if found is not None:
        return found
    return Alarm(code, "unknown", f"unknown alarm code 0x{code:02X}", True)


# ------------------------------------------------------------------ motor models
@dataclass(frozen=True)
class MotorModel:
    """One column of the manual's model tables (1)."""

    name: str
    supply_v: tuple[float, float]  # allowed DC supply range
    current_a: float  # rated supply current
    torque_nm: float  # rated torque
    rated_rpm: int
    max_rpm: int
    power_w: int
    multi_turn: bool  # multi-turn absolute encoder (with battery); else single-turn
    frame_mm: int  # flange size: the model name's leading number


def _pm10(v: float) -> tuple[float, float]:
    return round(v * 0.9, 2), round(v * 1.1, 2)


#: The models of section 1. Garbled names in the text ("42AI M15C", "60AII M25C") read
#: as 42AIM15C and 60AIM25C.
MODELS: tuple[MotorModel, ...] = (
    MotorModel("42AIM15C", _pm10(24), 2.2, 0.48, 1000, 1500, 50, False, 42),
    MotorModel("42AIM10C", _pm10(24), 1.6, 0.33, 1000, 1500, 35, False, 42),
    MotorModel("57AIM15C", (24.0, 36.0), 2.2, 0.48, 1000, 1500, 50, True, 57),
    MotorModel("57AIM15CH", (24.0, 36.0), 2.2, 0.24, 2000, 2500, 50, True, 57),
    MotorModel("57AIM30C", (24.0, 36.0), 4.4, 0.96, 1000, 1500, 100, True, 57),
    MotorModel("57AIM30CH", (24.0, 36.0), 4.4, 0.48, 2000, 2500, 100, True, 57),
    MotorModel("60AIM25C", _pm10(36), 7.4, 2.0, 1000, 1500, 200, False, 60),
    MotorModel("60AIM25CH", _pm10(36), 7.4, 1.0, 2000, 2500, 200, False, 60),
)
MODEL_BY_NAME: dict[str, MotorModel] = {m.name: m for m in MODELS}
DEFAULT_MODEL = "57AIM30C"


def model(name: str) -> MotorModel:
    try:
        return MODEL_BY_NAME[name.upper()]
    except KeyError:
        raise ArgumentRangeError(
            f"unknown YZ-AIM model {name!r}; known: {', '.join(MODEL_BY_NAME)}"
        ) from None
