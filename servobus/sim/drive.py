"""One-release alias (issue 19): the DMM virtual drive moved to :mod:`servobus.sim.dmm.drive`.

Docs examples before the simulator split import ``servobus.sim.drive.VirtualDrive``; new code
imports it from ``servobus.sim.dmm.drive`` (or ``servobus.sim``). Goes in the next release.
"""

from servobus.sim.dmm.drive import CONTROL_HZ, DEFAULT_AXIS_IDS, VirtualDrive

__all__ = ["CONTROL_HZ", "DEFAULT_AXIS_IDS", "VirtualDrive"]
