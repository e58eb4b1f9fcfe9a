"""servobus: codecs, clients, virtual drives and tools for DMM servo drives."""

from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    ConnectionLost,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    EepromGuardError,
    FramingError,
    NotSupported,
    ProtocolError,
    ServobusError,
)

__version__ = "0.1.0"

__all__ = [
    "ArgumentRangeError",
    "ChecksumError",
    "ConnectionLost",
    "DriveAlarm",
    "DriveError",
    "DriveTimeout",
    "EepromGuardError",
    "FramingError",
    "NotSupported",
    "ProtocolError",
    "ServobusError",
    "__version__",
]
