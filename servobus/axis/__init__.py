"""Host-side drivers: pure make_* commands, one async core per protocol, sync facades."""

from servobus.axis.base import AsyncAxis, Axis
from servobus.axis.connect import connect, connect_async

__all__ = ["AsyncAxis", "Axis", "connect", "connect_async"]
