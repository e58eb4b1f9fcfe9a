"""EEPROM of a virtual drive: parameters, config, id, per-item write counters.

Survives ``VirtualDrive.reset()``; with a path it is saved as JSON so it survives a restart
of the simulator (``servobus sim ... --state FILE``). Several drives may share one file:
each drive keeps its own record keyed by the id it had at power-on (its serial number).

Wear (manual 5.1: 1,000,000 guaranteed write cycles). Decision: writes are counted per item
(each parameter, ``config``, ``drive_id``, ``origin``); past ``EEPROM_CYCLE_LIMIT`` writes an
item's cell is worn out: further writes are still counted but no longer stick, so the value
read back after the next power cycle is the last one written before wear-out (the drive
keeps running on the value in RAM). :meth:`EepromStore.worn` reports it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from servobus.families.dmm import params as P

EEPROM_CYCLE_LIMIT = 1_000_000


class EepromStore:
    def __init__(self, path: str | Path | None = None, key: str = "0") -> None:
        self.path = Path(path) if path is not None else None
        self.key = key
        self.params: dict[str, int] = P.defaults()
        self.config = 0
        self.drive_id = 0
        self.origin = 0  # stored absolute zero: encoder angle within one revolution (counts)
        self.writes: dict[str, int] = {}
        self._initialised = False
        if self.path is not None and self.path.exists():
            self._load()

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
        return {"params": self.params, "config": self.config, "drive_id": self.drive_id,
                "origin": self.origin, "writes": self.writes}

    def save(self) -> None:
        if self.path is None:
            return
        data: dict[str, Any] = {}
        if self.path.exists():
            try:
                data = json.loads(self.path.read_text())
            except (OSError, ValueError):
                data = {}
        data[self.key] = self._record()
        tmp = self.path.with_suffix(self.path.suffix + ".tmp")
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
        tmp.replace(self.path)

    def _load(self) -> None:
        assert self.path is not None
        try:
            data = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return
        rec = data.get(self.key)
        if not isinstance(rec, dict):
            return
        self.params.update({k: int(v) for k, v in rec.get("params", {}).items()
                            if k in P.BY_NAME})
        self.config = int(rec.get("config", 0))
        self.drive_id = int(rec.get("drive_id", 0))
        self.origin = int(rec.get("origin", 0))
        self.writes = {k: int(v) for k, v in rec.get("writes", {}).items()}
        self._initialised = True
