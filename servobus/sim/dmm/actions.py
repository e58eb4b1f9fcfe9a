"""General_Read selectors that act instead of answering, shared by every front end.

DYN232M (docs/dyn232.md, from DMM's library) and DYN CAN (same firmware) use the same selectors:
0x1C reset (a power cycle), 0x20 servo enable, 0x21 servo disable. The readout selectors
(0x1B position, 0x1D speed, 0x1E torque) are scaled per protocol by each front end.
"""

from __future__ import annotations

from collections.abc import Callable

from servobus.families.dmm.vocabulary import GeneralReadSelector as GR
from servobus.sim.dmm.drive import VirtualDrive

ACTIONS: dict[GR, Callable[[VirtualDrive], object]] = {
    GR.RESET: VirtualDrive.reset,
    GR.ENABLE: VirtualDrive.enable,
    GR.DISABLE: VirtualDrive.disable,
}


def run_action(drive: VirtualDrive, selector: GR) -> bool:
    """Carry out an action selector; False when ``selector`` is a readout (or unknown)."""
    action = ACTIONS.get(selector)
    if action is None:
        return False
    action(drive)
    return True
