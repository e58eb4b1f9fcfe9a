"""The vocabulary DMM's two drive protocols share (DYN232M section 7, DYN CAN section 5).

DYN232M and DYN CAN run on the same firmware: function codes 0x00-0x0F mean the same on
both, ``General_Read`` takes the same one-byte selectors, and values have the same limits.
Both codecs build their function enums from :class:`DmmFunction` and read the limits here.
"""

from __future__ import annotations

from enum import Enum, IntEnum


class DmmFunction(IntEnum):
    """Function codes 0x00-0x0F, the same on DYN232M (7.2.4) and DYN CAN (5)."""

    SET_ORIGIN = 0x00
    GO_ABSOLUTE_POS = 0x01
    MAKE_LINEAR_LINE = 0x02
    GO_RELATIVE_POS = 0x03
    MAKE_CIRCULAR_ARC = 0x04
    ASSIGN_DRIVE_ID = 0x05
    READ_DRIVE_ID = 0x06
    SET_DRIVE_CONFIG = 0x07
    READ_DRIVE_CONFIG = 0x08
    READ_DRIVE_STATUS = 0x09
    TURN_CONST_SPEED = 0x0A
    SQUARE_WAVE = 0x0B
    SIN_WAVE = 0x0C
    SS_FREQUENCY = 0x0D
    GENERAL_READ = 0x0E
    FOR_MOTOR_DEFINE = 0x0F


class GeneralReadSelector(IntEnum):
    """The one data byte of General_Read (from DMM's own library; docs/dyn232.md)."""

    POSITION = 0x1B  # reply IS_ABS_POS32
    RESET = 0x1C  # drive reset (counts as a power cycle); no reply
    SPEED = 0x1D  # reply IS_SPEED (rpm)
    TORQUE = 0x1E  # reply IS_TRQ_CURRENT
    ENABLE = 0x20  # servo enable; no reply
    DISABLE = 0x21  # servo disable; no reply


class Kind(Enum):
    """What a command does, for the transaction policy."""

    MOTION = "motion"  # starts or changes motion: never re-sent automatically
    SETTING = "setting"  # writes EEPROM (parameter, config, id): counted by the EEPROM guard
    READ = "read"  # answered with a reply: safe to retry
    ACTION = "action"  # no reply, no EEPROM (origin, general-read actions)
    INTERNAL = "internal"


MAX_DRIVE_ID = 63  # six id bits on both protocols (DYN232M 7.2.3: 64..126 reserved)
VALUE_MIN = -(1 << 27)  # -134,217,728: 28-bit signed position/distance
VALUE_MAX = (1 << 27) - 1  # 134,217,727
# Turn_ConstSpeed, wave amplitude and frequency: the DYN232M manual gives only the wire
# length; servobus applies the ranges the DYN CAN manual gives for the same firmware.
CONST_SPEED_LIMIT_RPM = 20_000
WAVE_AMPLITUDE_MAX = 4_096  # 4096 = 180 deg of motor movement
WAVE_FREQUENCY_MAX_HZ = 50
