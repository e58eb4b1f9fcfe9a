"""Dyn232Axis: one DYN2/DC2/DYN4 drive on a DYN232M line, on the shared client
(:mod:`servobus.protocols.dyn232.client`); everything else is :class:`CommandAxis`."""

from __future__ import annotations

from typing import ClassVar

from servobus.families.dmm import units as U
from servobus.families.dmm.command_axis import CommandAxis, CommandSet
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232 import commands as cmds


class Dyn232Axis(CommandAxis):
    """One DYN2/DC2/DYN4 drive on a DYN232M line (everything is CommandAxis).

    The torque readout counts milliamperes (a servobus decision, docs/dyn232.md).
    """

    commands: ClassVar[CommandSet] = cmds
    protocol_name = "dyn232"
    drive_id_range = range(c.FACTORY_ID, c.MAX_DRIVE_ID + 1)
    amps_per_torque_unit = 1.0 / U.DYN232_TORQUE_UNITS_PER_A
