"""Host-side drivers: pure make_* commands, one async core per protocol, sync facades."""

from servobus.axis.base import AsyncAxis
from servobus.axis.connect import connect, connect_async
from servobus.axis.sync import Axis

__all__ = ["AsyncAxis", "Axis", "connect", "connect_async"]
