"""DMM DYN5 (EtherNet/IP option): Parameter object instances, Identity values, quirks.

Source: DMM "DYN5 EtherNet/IP Specification" 1.1A; section numbers below are that
manual's (4.1 general object behaviour, 4.2 Identity, 4.3 instance summary, 4.4 instance
details, 5 implicit I/O, 7 timing, Appendix B profile). See docs/enip.md.

ONE table, :data:`INSTANCES`, holds every Parameter object (class 0x0F) instance: name,
access, range, unit, meaning and what a Reset does to it. The EtherNet/IP codec, the
virtual adapter and the client all read it. Every instance has one attribute (1), a UDINT
on the wire; signed values travel as 32-bit two's complement (4.1: "All Parameter Class
Data Type is UDINT", while 4.3 gives negative ranges).

Decisions where the manual contradicts itself or is silent (each also at its entry):

* 0x22 EIP module firmware is "24" in the details table; it is 34 (0x22).
* Motor torque 0x1F: "981 = peak" in one sentence, the worked example divides by 2000:
  2000 = 100 % peak current (``servobus.families.dmm.units.DYN5_TORQUE_FULL_SCALE``). Its sign:
  positive = torque towards CCW (4.4 text and example agree), the opposite of the torque
  command 0x26 (positive = CW).
* Torque limit 0x20: 0~127 in 4.3, 1~127 in 4.4. 1..127 (4.4, the drive parameter table,
  127 = no limit); 0 would be a drive that cannot move.
* 0x14 motor speed is read-only, and 4.3 says writing it "returns 05 status error", while
  4.1 says writes to read-only objects have no effect and no error. The instance's own
  row wins: 0x14 answers 05, every other read-only instance ignores writes silently.
* 0x26 torque command is write-only (4.3), yet 4.4 says reading it "returns the command
  torque last sent": readable. 0x21 reset ("resets to 0x0000 after reset") stays
  write-only: reads give 0x12345 as 4.1 says for write-only objects.
* 0x01 memory test: "Int16" in 4.4, UDINT in 4.3: UDINT 0..63 like every instance.
* 0x03 set ABS origin "has no functionality when using single-turn system": the virtual
  drive models the multi-turn system (the only case where the instance does something).
  Reads return 0: a successful write resets the drive, which clears the instance.
* 0x0D software enable reads back 0xAAAA while the servo is enabled, 0xDEDE while free.
* Position ranges: +-134,217,728 in prose, -134217728~134217727 in 4.3: the 28-bit signed
  range. The readout "rolls back" past it: it wraps as a 28-bit two's complement number.
* 0xFF diagnostic counter: increments on each read and returns the new value (the first
  read after power-up returns 1), 255 rolls back to 0.
* GEAR_NUM / LINE_NUM / torque limit are "effective after power cycle or Reset" (4.4),
  yet every write is RAM-only and lost by that Reset (4.1): taken literally they could
  never take effect. The virtual drive applies them at once.
* Identity attribute 7 is "STRING[8]" (4.2: an ASCII array of 8 characters) but CIP's
  Identity product name is a SHORT_STRING (length byte + characters), which is what
  ListIdentity and every CIP scanner decode: SHORT_STRING, also for Get_Attribute_Single.
* Identity revision ("hardware and firmware revision code") is not given: 1.1, the
  manual's revision. The ListIdentity state byte (the manual lists attributes 1-7 only):
  3 = operational. Serial number 1 for every drive, as 4.2 says.
* EIP firmware value (format DDMMYYVVVV): 1506220011, a servobus choice (June 2022, 0011).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum

from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import StatusBits

FAMILY = "dyn5"

# ---------------------------------------------------------------- quirks (4.1, 4.4)
#: Reads of write-only, unreadable or non-existent instances return this value (4.1).
UNREADABLE = 0x12345
#: The one CIP general status the DYN5 answers for every refused request (4.1 "05 error").
ERROR_STATUS = 0x05
#: Parameter writes must carry exactly this many data bytes, else error 05 (4.1).
WRITE_SIZE = 4
ENABLE = 0xAAAA  # 0x0D / output image: software enable
DISABLE = 0xDEDE  # 0x0D / output image: software disable
RESET_KEY = 0xABCD  # 0x21: the only value that resets the drive
ORIGIN_KEY = 0xFFFF  # 0x03: the only value that sets the absolute origin
POSITION_SPEED_MODE = 0x0000  # 0x25
TORQUE_MODE = 0xFFFF  # 0x25
#: After a Reset the EtherNet/IP module is down for about 3 s (4.4, 0x21).
RESET_DOWNTIME_S = 3.0
#: Parameter instance numbers are one byte (0x01..0xFF); 0 addresses the class.
INSTANCE_MAX = 0xFF
PARAMETER_ATTRIBUTE = 1
#: 8 status bits are defined (b6, b7 reserved, high byte all zeros): b0..b5 (4.4, 0x02).
STATUS_MASK = int(StatusBits.OFF_POSITION | StatusBits.SERVO_FREE | StatusBits.ALARM_MASK
                  | StatusBits.MOTION_BUSY)
POSITION_BITS = 28  # absolute position range -2^27 .. 2^27-1
DIAGNOSTIC_COUNTER_MODULO = 256
EIP_FIRMWARE = 1506220011  # DDMMYYVVVV, servobus choice (module docstring)
TORQUE_FULL_SCALE = U.DYN5_TORQUE_FULL_SCALE  # 2000 = 100 % peak current
TORQUE_LIMIT_FULL = 127  # torque limit 127 = no limit; 64 = ~50 % peak (4.4, 0x20)

# ---------------------------------------------------------------- implicit I/O (5)
INPUT_ASSEMBLY = 100  # T->O, produced: position, speed, torque, status
OUTPUT_ASSEMBLY = 101  # O->T, consumed: enable/disable word behind the run/idle header
CONFIG_ASSEMBLY = 0  # "No Configuration Data": only instance 0 (or none) is accepted
INPUT_WORDS = 4  # UDINTs
OUTPUT_WORDS = 1
MIN_RPI_US = 5_000  # 7: minimum RPI 5 ms


# ---------------------------------------------------------------- Identity (4.2)
@dataclass(frozen=True)
class Identity:
    """Identity object (class 0x01, instance 1) attribute values."""

    vendor_id: int = 0xABCD
    device_type: int = 127
    product_code: int = 1
    revision: tuple[int, int] = (1, 1)  # major, minor
    status: int = 0
    serial_number: int = 1
    product_name: str = "DYN5ENIP"
    state: int = 3  # ListIdentity only (attribute 8 is not implemented): operational


IDENTITY = Identity()


# ---------------------------------------------------------------- Parameter object (4.3)
class Access(Enum):
    RW = "RW"  # setting or command that also reads back
    R = "R"  # readout
    W = "W"  # command; reads return UNREADABLE unless the entry says otherwise


class Kind(Enum):
    STORED = "stored"  # a RAM value of the EtherNet/IP module, no drive function
    PARAMETER = "parameter"  # a drive parameter (RAM copy; ``param`` names it)
    READOUT = "readout"  # live drive value
    COMMAND = "command"  # a write makes the drive act


@dataclass(frozen=True)
class Instance:
    """One Parameter object instance (attribute 1, UDINT)."""

    number: int
    name: str  # snake_case: CLI, Axis API
    title: str  # the manual's name
    access: Access
    kind: Kind
    minimum: int | None  # None: any 32-bit value (readouts without a stated range)
    maximum: int | None
    unit: str
    meaning: str
    ram: str  # what a Reset / power cycle does to it
    choices: tuple[int, ...] = ()  # the only accepted values (when not empty)
    param: str | None = None  # servobus.families.dmm.params name for Kind.PARAMETER
    pr: int | None = None  # the drive's parameter number [Pr.xx]
    readable: bool = True
    write_error: bool = False  # read-only, but a write answers 05 (0x14)
    default: int = 0  # power-up value of STORED / COMMAND values that read back

    @property
    def writable(self) -> bool:
        return self.access is not Access.R

    @property
    def signed(self) -> bool:
        return self.minimum is not None and self.minimum < 0

    def valid(self, value: int) -> bool:
        if self.choices:
            return value in self.choices
        if self.minimum is None or self.maximum is None:
            return True
        return self.minimum <= value <= self.maximum

    def check(self, value: int) -> int:
        """Return ``value`` if the drive accepts it, else raise ArgumentRangeError."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise ArgumentRangeError(f"{self.name} must be an integer, got {value!r}")
        if not self.writable:
            raise ArgumentRangeError(f"{self.name} (0x{self.number:02X}) is read-only")
        if not self.valid(value):
            raise ArgumentRangeError(
                f"{self.name} (0x{self.number:02X}) = {value} is outside {self.range_text()}")
        return value

    def range_text(self) -> str:
        if self.choices:
            return " or ".join(f"0x{c:04X}" for c in self.choices)
        if self.minimum is None or self.maximum is None:
            return "any 32-bit value"
        return f"{self.minimum}..{self.maximum} ({self.unit})"

    def encode(self, value: int) -> bytes:
        """The 4 wire bytes of ``value`` (two's complement when negative)."""
        return encode_udint(value)

    def decode(self, data: bytes) -> int:
        """Value of 4 wire bytes: signed for instances with a negative range."""
        raw = decode_udint(data)
        return to_signed32(raw) if self.signed else raw


_RW, _R, _W = Access.RW, Access.R, Access.W
_ST, _PA, _RO, _CM = Kind.STORED, Kind.PARAMETER, Kind.READOUT, Kind.COMMAND
_POS = (-(1 << (POSITION_BITS - 1)), (1 << (POSITION_BITS - 1)) - 1)
_LOST = "lost at Reset / power cycle (RAM)"
_EEPROM = "RAM copy; a Reset reloads the value saved by DMMDRV5"
_LIVE = "live value"
_ONCE = "command, acts once"

#: THE DYN5 Parameter object instance table (4.3/4.4, corrected as the docstring says).
INSTANCES: tuple[Instance, ...] = (
    Instance(0x01, "memory_test", "NA (Memory Test Object)", _RW, _ST, 0, 63, "-",
             "any value written reads back; no drive function", _LOST + ", reads 0"),
    Instance(0x02, "drive_status", "Drive Status", _R, _RO, 0, 65535, "bits",
             "status word: b0 off position, b1 servo free, b4..b2 alarm, b5 S-curve "
             "running; b6, b7 and the high byte are 0", _LIVE),
    Instance(0x03, "set_abs_origin", "Set ABS Origin", _RW, _CM, None, None, "-",
             "0xFFFF: the current position becomes the absolute zero (multi-turn), then "
             "the servo control resets at that position; reads 0", _ONCE,
             choices=(ORIGIN_KEY,)),
    Instance(0x04, "main_gain", "Main Gain", _RW, _PA, 1, 127, "-",
             "position loop gain [Pr.00]; on the fly", _EEPROM, param="main_gain", pr=0),
    Instance(0x05, "speed_gain", "Speed Gain", _RW, _PA, 1, 127, "-",
             "speed loop gain [Pr.01]; on the fly", _EEPROM, param="speed_gain", pr=1),
    Instance(0x06, "integration_gain", "Integration Gain", _RW, _PA, 1, 127, "-",
             "speed loop integrator gain [Pr.02]; on the fly", _EEPROM,
             param="int_gain", pr=2),
    Instance(0x07, "torque_filter_constant", "Torque Filter Constant", _RW, _PA, 1, 127,
             "-", "torque filter a = 26 x value rad/s [Pr.03] (4.4 calls it Torque "
             "Constant); on the fly", _EEPROM, param="trq_cons", pr=3),
    Instance(0x08, "high_speed", "High Speed", _RW, _PA, 1, 127, "(v+3)^2/16*12.21 rpm",
             "profile maximum speed [Pr.07] (Appendix B); on the fly", _EEPROM,
             param="max_speed", pr=7),
    Instance(0x09, "high_accel", "High Accel", _RW, _PA, 1, 127, "v*635.78 rpm/s",
             "profile and speed-command acceleration [Pr.11] (Appendix B); on the fly",
             _EEPROM, param="max_accel", pr=11),
    Instance(0x0A, "on_position_range", "On Position Range", _RW, _PA, 1, 127,
             "1/16384 rev", "on-position window [Pr.15] (status b0)", _EEPROM,
             param="on_range", pr=15),
    Instance(0x0B, "gear_num", "GEAR_NUM", _RW, _PA, 1, 16384, "4 x GEAR_NUM cmd/rev",
             "electronic gear [Pr.19]: movement = command x 4096/GEAR_NUM x 4 counts",
             _EEPROM, param="gear_num", pr=19),
    Instance(0x0C, "line_num", "LINE_NUM", _RW, _PA, 1, 4095, "-",
             "encoder output resolution [Pr.20]: x4 pulses/rev (2048..4095: (v-2047) x 4)",
             _EEPROM, param="line_num", pr=20),
    Instance(0x0D, "sw_enable", "Drive SW Enable/Disable", _RW, _CM, None, None, "-",
             "0xAAAA enables, 0xDEDE disables the servo; reads the current state",
             "enabled after Reset / power-up", choices=(ENABLE, DISABLE), default=ENABLE),
    Instance(0x0E, "turn_const_speed", "Turn_ConstSpeed", _W, _CM, -16384, 16384, "rpm",
             "run at this speed (+ = CW), ramping at High Accel; 0 stops", _ONCE, readable=False),
    Instance(0x0F, "square_wave_amplitude", "Square_Wave Motion Amplitude", _W, _CM, 0,
             4096, "4096 = 180 deg", "start a square wave (send SS_Frequency first)",
             _ONCE, readable=False),
    Instance(0x11, "sine_wave_amplitude", "Sin_Wave Motion Amplitude", _W, _CM, 0, 4096,
             "4096 = 180 deg", "start a sine wave (send SS_Frequency first)", _ONCE,
             readable=False),
    Instance(0x13, "ss_frequency", "SS_Frequency", _W, _CM, 0, 60, "Hz",
             "square / sine wave frequency", _LOST, readable=False),
    Instance(0x14, "motor_speed", "Motor Speed", _R, _RO, -16384, 16384, "rpm",
             "motor speed (+ = CW); a write answers 05", _LIVE, write_error=True),
    Instance(0x15, "go_absolute_pos", "Go_Absolute_Pos_Profile Command", _W, _CM, *_POS,
             "command units", "profile move to an absolute position (Appendix B, DTPU)",
             _ONCE, readable=False),
    Instance(0x17, "go_relative_pos", "Go_Relative_Pos_Profile Command", _W, _CM, *_POS,
             "command units", "profile move by a distance (Appendix B, DTPU)", _ONCE,
             readable=False),
    Instance(0x1D, "motor_position", "Motor Absolute Position", _R, _RO, *_POS, "counts",
             "absolute position, 65,536 counts/rev (+ = CW); wraps at 28 bits", _LIVE),
    Instance(0x1F, "motor_torque", "Motor Torque", _R, _RO, -TORQUE_FULL_SCALE,
             TORQUE_FULL_SCALE, "2000 = peak current", "output current (+ = CCW)", _LIVE),
    Instance(0x20, "torque_limit", "Torque Limit (Global)", _RW, _PA, 1, TORQUE_LIMIT_FULL,
             "127 = no limit", "current limit [Pr.04], value/127 of peak current",
             _EEPROM, param="torque_limit", pr=4),
    Instance(0x21, "drive_reset", "Drive Reset", _W, _CM, None, None, "-",
             "0xABCD resets the drive (EtherNet/IP down ~3 s, RAM settings lost)", _ONCE,
             choices=(RESET_KEY,), readable=False),
    Instance(0x22, "eip_firmware", "EIP Module Firmware", _R, _RO, None, None,
             "DDMMYYVVVV", "EtherNet/IP module firmware date and version", "constant",
             default=EIP_FIRMWARE),
    Instance(0x25, "command_mode", "Command Mode Switch", _RW, _CM, None, None, "-",
             "0x0000 position/speed mode, 0xFFFF torque mode", "position/speed after Reset",
             choices=(POSITION_SPEED_MODE, TORQUE_MODE), default=POSITION_SPEED_MODE),
    Instance(0x26, "torque_command", "Torque Command", _W, _CM, -TORQUE_FULL_SCALE,
             TORQUE_FULL_SCALE, "2000 = peak current",
             "torque mode current command (+ = CW); reads the last command", _LOST,
             readable=True),
    Instance(0x27, "torque_speed_limit", "Torque Mode Speed Limit", _RW, _ST, 1, 20000,
             "rpm", "speed limit in torque mode", _LOST, default=20000),
    Instance(0xFF, "diagnostic_counter", "Diagnostic Counter", _R, _RO, 0, 255, "-",
             "increments on every read, 255 rolls back to 0", "0 after Reset"),
)

BY_NUMBER: dict[int, Instance] = {i.number: i for i in INSTANCES}
BY_NAME: dict[str, Instance] = {i.name: i for i in INSTANCES}


def instance(key: int | str) -> Instance:
    """Look an instance up by number or snake_case name (ArgumentRangeError if unknown)."""
    found = BY_NUMBER.get(key) if isinstance(key, int) else BY_NAME.get(key)
    if found is None:
        raise ArgumentRangeError(
            f"unknown DYN5 parameter instance {key!r}; known: {', '.join(BY_NAME)}")
    return found


# ---------------------------------------------------------------- wire and unit helpers
_UDINT = struct.Struct("<I")


def encode_udint(value: int) -> bytes:
    """UDINT little-endian; negative values as 32-bit two's complement."""
    if not -(1 << 31) <= value <= 0xFFFF_FFFF:
        raise ArgumentRangeError(f"{value} does not fit 32 bits")
    return _UDINT.pack(value & 0xFFFF_FFFF)


def decode_udint(data: bytes) -> int:
    if len(data) != 4:
        raise ArgumentRangeError(f"a UDINT is 4 bytes, got {len(data)}")
    return int(_UDINT.unpack(data)[0])


def to_signed32(raw: int) -> int:
    return raw - (1 << 32) if raw & 0x8000_0000 else raw


def wrap_position(counts: int) -> int:
    """The readout's 28-bit two's complement wrap (module docstring)."""
    half = 1 << (POSITION_BITS - 1)
    return (counts + half) % (1 << POSITION_BITS) - half


def torque_to_amps(value: float, peak_current_a: float) -> float:
    """Torque units (2000 = 100 % peak) to amperes (4.4 0x1F / 0x26 examples)."""
    return value / TORQUE_FULL_SCALE * peak_current_a


def amps_to_torque(amps: float, peak_current_a: float) -> int:
    """Amperes to torque units, clamped to +-2000."""
    value = round(amps / peak_current_a * TORQUE_FULL_SCALE)
    return max(-TORQUE_FULL_SCALE, min(TORQUE_FULL_SCALE, value))


def torque_limit_amps(limit: int, peak_current_a: float) -> float:
    """Peak output current allowed by the torque limit (4.4 0x20: 127 = no limit)."""
    return min(limit, TORQUE_LIMIT_FULL) / TORQUE_LIMIT_FULL * peak_current_a
