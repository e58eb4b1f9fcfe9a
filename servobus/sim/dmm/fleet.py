"""Build the virtual DMM drives a server or an in-process ``sim://`` line holds (any protocol)."""

from __future__ import annotations

from collections.abc import Sequence

from servobus.families.dmm import units as U
from servobus.families.dmm.vocabulary import MAX_DRIVE_ID
from servobus.sim.core.ids import parse_ids
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.eeprom import EepromStore


def parse_drive_ids(text: str) -> tuple[int, ...]:
    """``"1,2,3"`` -> (1, 2, 3): DMM drive ids 0..63 (six id bits on both protocols)."""
    return parse_ids(text, min_id=0, max_id=MAX_DRIVE_ID)


def make_drives(ids: Sequence[int], *, state: str | None = None,
                model: str = U.DEFAULT_MODEL) -> list[VirtualDrive]:
    """One VirtualDrive per id; with ``state`` each keeps its EEPROM under key str(id)."""
    return [VirtualDrive(i, model=model,
                         eeprom=EepromStore(state, key=str(i)) if state else None)
            for i in ids]
