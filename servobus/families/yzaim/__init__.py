"""YZ-AIM family: the register map, models and alarms (registers.py) and the Axis view
(family.py).

One-release alias (issue 19): ``servobus.families.yzaim`` was the register table module; its
names are re-exported here until the next release. New code imports
``servobus.families.yzaim.registers``.
"""

from servobus.families.yzaim.registers import *  # noqa: F403
