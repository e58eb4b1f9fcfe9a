"""EEPROM of a virtual DMM drive: parameters, config, id, per-item write counters.

Survives ``VirtualDrive.reset()``; with a path it is saved as JSON so it survives a restart
of the simulator (``servobus sim ... --state FILE``), in the state file of
:mod:`servobus.sim.core.state_file` (checked whole, locked, written atomically). Several
drives may share one file: each drive keeps its own record keyed by the id it had at
power-on (its serial number).

Wear (manual 5.1: 1,000,000 guaranteed write cycles). Decision: writes are counted per item
(each parameter, ``config``, ``drive_id``, ``origin``); past ``EEPROM_CYCLE_LIMIT`` writes an
item's cell is worn out: further writes are still counted but no longer stick, so the value
read back after the next power cycle is the last one written before wear-out (the drive
keeps running on the value in RAM). :meth:`EepromStore.worn` reports it.

A valid file (:data:`DMM_STATE`) is a JSON object mapping power-on ids ("0".."63") to
records ``{"drive_id": 0..63, "params": {name: value}, "config": 0..0x3F, "origin":
0..65535, "writes": {item: count >= 0}}``; ``drive_id`` is required, the rest optional
(defaults); every parameter must be a known EEPROM parameter inside its range in
:mod:`servobus.families.dmm.params`; values are integers (not booleans, not floats); no
other keys.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from servobus.families.dmm import params as P
from servobus.families.dmm.registers import CONFIG_DEFINED_MASK
from servobus.families.dmm.units import COUNTS_PER_REV
from servobus.families.dmm.vocabulary import MAX_DRIVE_ID
from servobus.sim.core.state_file import RecordStore, StateKind, checked_int, describe

EEPROM_CYCLE_LIMIT = 1_000_000
_FIELDS = frozenset({"drive_id", "params", "config", "origin", "writes"})
_ITEMS = frozenset({*P.BY_NAME, "config", "drive_id", "origin"})  # what write counters count


def check_record(key: str, rec: object) -> dict[str, Any]:
    """One record, normalised (every field present); ValueError names the first problem."""
    if not (key.isdigit() and key == str(int(key)) and int(key) <= MAX_DRIVE_ID):
        raise ValueError(f"the key must be a power-on drive id 0..{MAX_DRIVE_ID}")
    return check_drive_record(rec)


def check_drive_record(rec: object) -> dict[str, Any]:
    """One record's fields (whatever its key), normalised; ValueError names the problem."""
    if not isinstance(rec, dict):
        raise ValueError(f"must be an object, got {describe(rec)}")
    unknown = sorted(set(rec) - _FIELDS)
    if unknown:
        raise ValueError(f"unknown field {unknown[0]!r}")
    if "drive_id" not in rec:
        raise ValueError("has no drive_id")
    out: dict[str, Any] = {
        "drive_id": checked_int(rec["drive_id"], "drive_id", 0, MAX_DRIVE_ID),
        "config": checked_int(rec.get("config", 0), "config", 0, CONFIG_DEFINED_MASK),
        "origin": checked_int(rec.get("origin", 0), "origin", 0, COUNTS_PER_REV - 1),
    }
    params = rec.get("params", {})
    if not isinstance(params, dict):
        raise ValueError(f"params must be an object, got {describe(params)}")
    checked = P.defaults()
    for name, value in params.items():
        spec = P.BY_NAME.get(name)
        if spec is None or spec.storage is not P.Storage.EEPROM:
            raise ValueError(f"{name!r} is not an EEPROM parameter")
        checked[name] = checked_int(value, name, spec.minimum, spec.maximum)
    out["params"] = checked
    writes = rec.get("writes", {})
    if not isinstance(writes, dict):
        raise ValueError(f"writes must be an object, got {describe(writes)}")
    for item, count in writes.items():
        if item not in _ITEMS:
            raise ValueError(f"writes counts an unknown item {item!r}")
        checked_int(count, f"writes[{item!r}]", 0, 1 << 62)
    out["writes"] = dict(writes)
    return out


DMM_STATE = StateKind("drive records", check_record)


# ---------------------------------------------------------------- the store
class EepromStore(RecordStore):
    def __init__(self, path: str | Path | None = None, key: str = "0",
                 kind: StateKind = DMM_STATE) -> None:
        self.params: dict[str, int] = P.defaults()
        self.config = 0
        self.drive_id = 0
        self.origin = 0  # stored absolute zero: encoder angle within one revolution (counts)
        self.writes: dict[str, int] = {}
        self._initialised = False
        super().__init__(path, key, kind)

    def setdefault_drive(self, drive_id: int) -> None:
        """Factory id for a fresh EEPROM (ignored when a stored state was loaded)."""
        if not self._initialised:
            self.drive_id = drive_id
            self._initialised = True

    def _count(self, item: str) -> bool:
        """Count one write; False when the item's cell is worn out (the write is lost)."""
        self.writes[item] = self.writes.get(item, 0) + 1
        return self.writes[item] <= EEPROM_CYCLE_LIMIT

    def worn(self, item: str) -> bool:
        return self.writes.get(item, 0) >= EEPROM_CYCLE_LIMIT

    def write_param(self, name: str, value: int) -> bool:
        """Write one parameter; returns False when the cell is worn out (value not stored)."""
        stored = self._count(name)
        if stored:
            self.params[name] = value
        self.save()
        return stored

    def write_config(self, value: int) -> None:
        if self._count("config"):
            self.config = value
        self.save()

    def write_id(self, drive_id: int) -> None:
        if self._count("drive_id"):
            self.drive_id = drive_id
        self.save()

    def write_origin(self, angle: int) -> None:
        if self._count("origin"):
            self.origin = angle
        self.save()

    def _record(self) -> dict[str, Any]:
        return {"params": dict(self.params), "config": self.config, "drive_id": self.drive_id,
                "origin": self.origin, "writes": dict(self.writes)}

    def _restore(self, rec: dict[str, Any]) -> None:
        self.params.update(rec["params"])
        self.config = rec["config"]
        self.drive_id = rec["drive_id"]
        self.origin = rec["origin"]
        self.writes = dict(rec["writes"])
        self._initialised = True
