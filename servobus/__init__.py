"""servobus: codecs, clients, virtual drives and tools for DMM servo drives."""

from typing import TYPE_CHECKING

from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    ConnectionLost,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    EepromGuardError,
    FramingError,
    LimitError,
    MachineFileError,
    MachineLinkError,
    NotSupported,
    ProtocolError,
    ServobusError,
)

if TYPE_CHECKING:
    from servobus.machine import open_machine, open_machine_async

__version__ = "0.1.0"


def __getattr__(name: str) -> object:
    """``servobus.connect`` / ``connect_async`` without loading the Axis on ``import servobus``."""
    if name in ("connect", "connect_async"):
        import importlib

        return getattr(importlib.import_module("servobus.axis.connect"), name)
    if name in ("open_machine", "open_machine_async"):  # servobus.machine, loaded when used
        import importlib

        return getattr(importlib.import_module("servobus.machine"), name)
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
    "LimitError",
    "MachineFileError",
    "MachineLinkError",
    "NotSupported",
    "ProtocolError",
    "ServobusError",
    "__version__",
    "connect",
    "connect_async",
    "open_machine",
    "open_machine_async",
]
