"""The vendor-neutral Axis API: AsyncAxis, the sync facade Axis, connect(); its value types
(types.py). It names no family and no protocol: the families write their profiles on it
(servobus.families.<f>.axis), the registry finds the protocols."""

from servobus.axis.base import AsyncAxis
from servobus.axis.capabilities import Capability
from servobus.axis.connect import connect, connect_async
from servobus.axis.sync import Axis

__all__ = ["AsyncAxis", "Axis", "Capability", "connect", "connect_async"]
