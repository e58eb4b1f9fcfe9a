"""The built-in virtual machine: what the CLI, the GUI and the demo run on without a file.

Two DMM DYN2 axes on one virtual RS-485 line (DYN232M) - a gantry's x and y in mm on 5 mm
lead screws - and one YZ-AIM integrated servo on a virtual CAN bus (EasyCan) as a rotary
axis c in degrees. In-process (``sim://``), unpaced (``fast=1``), gone when closed.
"""

from __future__ import annotations

from servobus.machine.config import MachineSpec, parse_machine

BUILTIN_SOURCE = "<built-in virtual machine>"

BUILTIN_TOML = """\
name = "virtual-cell"

[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]
speed = 50.0
label = "gantry x, DMM DYN2 on RS-485"

[axes.y]
url = "sim://dyn232?fast=1"
id = 2
unit = "mm"
per_rev = 5.0
limits = [-10.0, 200.0]
speed = 50.0
label = "gantry y, DMM DYN2 on RS-485"

[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
limits = [-720.0, 720.0]
speed = 180.0
label = "rotary c, YZ-AIM on CAN"
"""

#: One stderr line when a command ran on it (as the single built-in drive is announced).
BUILTIN_NOTE = ("note: no machine or drive named (--machine, SERVOBUS_MACHINE, --url ...): this "
                "ran on the built-in virtual machine (x, y: DMM on one RS-485 line, c: YZ-AIM "
                "on CAN), which is gone now")


def builtin_spec() -> MachineSpec:
    return parse_machine(BUILTIN_TOML, source=BUILTIN_SOURCE)
