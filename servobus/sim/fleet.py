"""Build the virtual drives a server or an in-process ``sim://`` line holds (any protocol)."""

from __future__ import annotations

from collections.abc import Sequence

from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.families.dmm.vocabulary import MAX_DRIVE_ID
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.eeprom import EepromStore

DEFAULT_MAX_ID = MAX_DRIVE_ID  # DMM: six id bits on both protocols


def parse_ids(text: str, *, min_id: int = 0, max_id: int = DEFAULT_MAX_ID) -> tuple[int, ...]:
    """``"1,2,3"`` -> (1, 2, 3); each in ``min_id..max_id``, no duplicates."""
    try:
        ids = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise ArgumentRangeError(f"drive ids must be integers, got {text!r}") from None
    if not ids:
        raise ArgumentRangeError("at least one drive id is needed")
    bad = [i for i in ids if not min_id <= i <= max_id]
    if bad:
        raise ArgumentRangeError(f"drive ids {bad} are outside {min_id}..{max_id}")
    if len(set(ids)) != len(ids):
        raise ArgumentRangeError(f"duplicate drive ids in {text!r}")
    return ids


def make_drives(ids: Sequence[int], *, state: str | None = None,
                model: str = U.DEFAULT_MODEL) -> list[VirtualDrive]:
    """One VirtualDrive per id; with ``state`` each keeps its EEPROM under key str(id)."""
    return [VirtualDrive(i, model=model,
                         eeprom=EepromStore(state, key=str(i)) if state else None)
            for i in ids]
