"""Status and configuration registers (DYN2 manual 7.3, DYN CAN section 6, DYN5 status).

One definition of every bit; codecs carry the byte, clients and the simulator use these types.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, IntFlag


class StatusBits(IntFlag):
    OFF_POSITION = 0x01  # b0: 1 = busy / |Pset - Pmotor| > OnRange
    SERVO_FREE = 0x02  # b1: 1 = motor free (servo disabled)
    ALARM_MASK = 0x1C  # b4..b2: alarm code
    MOTION_BUSY = 0x20  # b5: built-in S-curve / linear / circular motion running
    JP3_PIN2 = 0x40  # b6: JP3 pin 2 input level


ALARM_SHIFT = 2


class AlarmCode(IntEnum):
    NONE = 0
    LOST_PHASE = 1  # |Pset - Pmotor| > 8192 (1/16384 rev) or >= 90 deg for ~2 s
    OVER_CURRENT = 2
    OVERHEAT = 3  # overheat or over power (I^2 t)
    CHECKSUM = 4  # bad checksum; command refused; cleared when the status is read
    OVER_VOLTAGE = 5  # DYN2 lists 5..7 as TBD; DYN5 defines 5 = over voltage: used for all

    @property
    def latching(self) -> bool:
        """Real alarms latch until reset; the checksum code is a one-read notice."""
        return self not in (AlarmCode.NONE, AlarmCode.CHECKSUM)


@dataclass(frozen=True)
class DriveStatus:
    on_position: bool = True
    servo_free: bool = False
    alarm: AlarmCode = AlarmCode.NONE
    motion_busy: bool = False
    jp3_pin2: bool = False

    def to_byte(self) -> int:
        b = 0
        if not self.on_position:
            b |= StatusBits.OFF_POSITION
        if self.servo_free:
            b |= StatusBits.SERVO_FREE
        b |= (int(self.alarm) & 0x07) << ALARM_SHIFT
        if self.motion_busy:
            b |= StatusBits.MOTION_BUSY
        if self.jp3_pin2:
            b |= StatusBits.JP3_PIN2
        return b

    @classmethod
    def from_byte(cls, value: int) -> DriveStatus:
        """The status a byte reads as; one shared (frozen) instance per byte value: the
        decoding (five IntFlag operations) was a tenth of a CAN status read's CPU."""
        status = _STATUS_BY_BYTE.get(value)
        if status is None:
            status = cls._decode(value)
            if 0 <= value <= 0xFF:
                _STATUS_BY_BYTE[value] = status
        return status

    @classmethod
    def _decode(cls, value: int) -> DriveStatus:
        code = (value & StatusBits.ALARM_MASK) >> ALARM_SHIFT
        try:
            alarm = AlarmCode(code)
        except ValueError:  # 6, 7: TBD in the manual; keep the number visible
            alarm = AlarmCode.NONE if code == 0 else AlarmCode(5)
        return cls(
            on_position=not value & StatusBits.OFF_POSITION,
            servo_free=bool(value & StatusBits.SERVO_FREE),
            alarm=alarm,
            motion_busy=bool(value & StatusBits.MOTION_BUSY),
            jp3_pin2=bool(value & StatusBits.JP3_PIN2),
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "on_position": self.on_position,
            "servo_free": self.servo_free,
            "alarm": self.alarm.name.lower(),
            "alarm_code": int(self.alarm),
            "motion_busy": self.motion_busy,
            "jp3_pin2": self.jp3_pin2,
        }


_STATUS_BY_BYTE: dict[int, DriveStatus] = {}


class ConfigBits(IntFlag):
    COMMAND_MODE_MASK = 0x03  # b1 b0
    ABSOLUTE = 0x04  # b2: absolute position system (return to stored zero at power-on)
    SERVO_MODE_MASK = 0x18  # b4 b3
    FREE = 0x20  # b5: 1 = motor free (servo disabled)


#: Bits the config byte defines (b7 b6 are TBD / unimplemented); ``from_byte`` ignores the rest.
CONFIG_DEFINED_MASK = 0x3F


class CommandMode(IntEnum):
    RS232 = 0
    CW_CCW = 1
    PULSE_DIR = 2
    ANALOG = 3


class ServoMode(IntEnum):
    POSITION = 0
    SPEED = 1
    TORQUE = 2
    TBD = 3


@dataclass(frozen=True)
class DriveConfig:
    command_mode: CommandMode = CommandMode.RS232
    absolute: bool = False
    servo_mode: ServoMode = ServoMode.POSITION
    free: bool = False

    def to_byte(self) -> int:
        b = int(self.command_mode) & 0x03
        if self.absolute:
            b |= ConfigBits.ABSOLUTE
        b |= (int(self.servo_mode) & 0x03) << 3
        if self.free:
            b |= ConfigBits.FREE
        return b

    @classmethod
    def from_byte(cls, value: int) -> DriveConfig:
        return cls(
            command_mode=CommandMode(value & 0x03),
            absolute=bool(value & ConfigBits.ABSOLUTE),
            servo_mode=ServoMode((value >> 3) & 0x03),
            free=bool(value & ConfigBits.FREE),
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "command_mode": self.command_mode.name.lower(),
            "absolute": self.absolute,
            "servo_mode": self.servo_mode.name.lower(),
            "free": self.free,
        }
