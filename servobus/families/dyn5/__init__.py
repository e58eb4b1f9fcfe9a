"""DMM DYN5 family: the Parameter object instance table (params.py) and the Axis view
(family.py).

One-release alias (issue 19): ``servobus.families.dyn5`` was the instance table module; its
names are re-exported here until the next release. New code imports
``servobus.families.dyn5.params``.
"""

from servobus.families.dyn5.params import *  # noqa: F403
