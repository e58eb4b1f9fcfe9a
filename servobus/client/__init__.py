"""Host-side drivers: pure make_* commands, one async core per protocol, sync facades."""

from servobus.client.axis import AsyncAxis, Axis
from servobus.client.connect import connect, connect_async

__all__ = ["AsyncAxis", "Axis", "connect", "connect_async"]
