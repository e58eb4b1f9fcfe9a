"""One-release alias (issue 19): the YZ-AIM virtual motor moved to :mod:`servobus.sim.yzaim.motor`.

Docs examples before the simulator split import ``servobus.sim.yzaim_motor.YzaimMotor``; new
code imports it from ``servobus.sim.yzaim.motor``. Goes in the next release.
"""

from servobus.sim.yzaim.motor import MotorRefused, Refusal, YzaimMotor

__all__ = ["MotorRefused", "Refusal", "YzaimMotor"]
