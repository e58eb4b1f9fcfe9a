"""servobus: codecs, clients, virtual drives and tools for DMM servo drives."""

from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    EepromGuardError,
    FramingError,
    ProtocolError,
    ServobusError,
)

__version__ = "0.1.0"

__all__ = [
    "ArgumentRangeError",
    "ChecksumError",
    "DriveAlarm",
    "DriveError",
    "DriveTimeout",
    "EepromGuardError",
    "FramingError",
    "ProtocolError",
    "ServobusError",
    "__version__",
]
