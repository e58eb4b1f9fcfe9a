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


def __getattr__(name: str) -> object:
    """``servobus.connect`` / ``connect_async`` without loading the Axis on ``import servobus``."""
    if name in ("connect", "connect_async"):
        import importlib

        return getattr(importlib.import_module("servobus.axis.connect"), name)
    raise AttributeError(f"module 'servobus' has no attribute {name!r}")

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
    "connect",
    "connect_async",
]
