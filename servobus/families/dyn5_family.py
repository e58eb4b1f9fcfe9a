"""One-release alias (issue 19): moved to :mod:`servobus.families.dyn5.family`."""

from servobus.families.dyn5.family import *  # noqa: F403
from servobus.families.dyn5.family import DYN5, PARAM_INSTANCES, PARAM_NAMES, axis_status

__all__ = ["DYN5", "PARAM_INSTANCES", "PARAM_NAMES", "axis_status"]
