"""servobus: codecs, clients, virtual drives and tools for industrial servo drives (DMM, YZ-AIM)."""

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

__version__ = "0.2.0"

# ``import servobus`` stays light (about 2 ms; the Axis and asyncio take about 50 ms more,
# `python -X importtime`), so connect/connect_async load on first use. Checkers see the
# real functions through the TYPE_CHECKING import; the module __getattr__ is hidden from
# them, so a misspelt ``servobus.conect`` is a checker error too. A local TYPE_CHECKING
# (checkers take any name TYPE_CHECKING as true) spares the 2 ms of importing typing.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from servobus.axis.connect import connect, connect_async
    from servobus.machine import open_machine, open_machine_async
else:
    def __getattr__(name: str) -> object:
        """``servobus.connect`` / ``connect_async``, imported on first use."""
        if name in ("connect", "connect_async"):
            import importlib

            return getattr(importlib.import_module("servobus.axis.connect"), name)
        if name in ("open_machine", "open_machine_async"):  # servobus.machine, on first use
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
