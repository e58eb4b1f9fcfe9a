"""One-release alias (issue 19): moved to :mod:`servobus.families.yzaim.family`."""

from servobus.families.yzaim.family import *  # noqa: F403
from servobus.families.yzaim.family import PARAM_NAMES, YZAIM, axis_status

__all__ = ["PARAM_NAMES", "YZAIM", "axis_status"]
