"""EEPROM of a virtual drive: parameters, config, id, per-item write counters.

Survives ``VirtualDrive.reset()``; with a path it is saved as JSON so it survives a restart
of the simulator (``servobus sim ... --state FILE``). Several drives may share one file:
each drive keeps its own record keyed by the id it had at power-on (its serial number).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from servobus.drive import params as P

EEPROM_CYCLE_LIMIT = 1_000_000


class EepromStore:
    def __init__(self, path: str | Path | None = None, key: str = "0") -> None:
        self.path = Path(path) if path is not None else None
        self.key = key
        self.params: dict[str, int] = P.defaults()
        self.config = 0
        self.drive_id = 0
        self.writes: dict[str, int] = {}
        self._initialised = False
        if self.path is not None and self.path.exists():
            self._load()

    def setdefault_drive(self, drive_id: int) -> None:
        """Factory id for a fresh EEPROM (ignored when a stored state was loaded)."""
        if not self._initialised:
            self.drive_id = drive_id
            self._initialised = True

    def _count(self, item: str) -> None:
        self.writes[item] = self.writes.get(item, 0) + 1

    def write_param(self, name: str, value: int) -> None:
        self.params[name] = value
        self._count(name)
        self.save()

    def write_config(self, value: int) -> None:
        self.config = value
        self._count("config")
        self.save()

    def write_id(self, drive_id: int) -> None:
        self.drive_id = drive_id
        self._count("drive_id")
        self.save()

    def _record(self) -> dict[str, Any]:
        return {"params": self.params, "config": self.config, "drive_id": self.drive_id,
                "writes": self.writes}

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
        self.writes = {k: int(v) for k, v in rec.get("writes", {}).items()}
        self._initialised = True
