"""EEPROM of a virtual YZ-AIM motor: the saved registers, the recorded position, write count.

The motor writes it only when the host sets the save flag 0x14 (manual 5.2) - every saved
register at once - and records its position at power-off (1: "communication mode: power-off
record position"). With a path it is kept as JSON so it survives a restart of the simulator
(``servobus sim easycan --state FILE``). Several motors may share one file: each keeps its own
record under the address it had when the record was made (its serial number), like
:class:`servobus.sim.eeprom.EepromStore` for DMM drives.

File format (decision): ``{"<key>": {"registers": {name: raw value}, "position": counts,
"saves": n}}``. A record that cannot be read, or a register that is not a saved register of
the family table or is out of its range, is ignored (the table default is used) rather than
served: the motor never runs on a value it could not have stored.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from servobus.families import yzaim


class YzaimStore:
    def __init__(self, path: str | Path | None = None, key: str = "1") -> None:
        self.path = Path(path) if path is not None else None
        self.key = key
        self.registers: dict[str, int] = {
            r.name: r.default for r in yzaim.SAVED if r.default is not None}
        self.position: int | None = None  # counts recorded at the last power-off
        self.saves = 0
        self.loaded = False
        if self.path is not None and self.path.exists():
            self._load()

    def save_registers(self, values: dict[str, int]) -> None:
        """The save flag: every saved register of ``values`` goes to EEPROM at once."""
        for reg in yzaim.SAVED:
            if reg.name in values:
                self.registers[reg.name] = values[reg.name]
        self.saves += 1
        self.save()

    def record_position(self, counts: int) -> None:
        self.position = counts
        self.save()

    def _record(self) -> dict[str, Any]:
        return {"registers": dict(self.registers), "position": self.position,
                "saves": self.saves}

    def save(self) -> None:
        if self.path is None:
            return
        data: dict[str, Any] = {}
        if self.path.exists():
            try:
                loaded = json.loads(self.path.read_text())
                data = loaded if isinstance(loaded, dict) else {}
            except (OSError, ValueError):
                data = {}
        data[self.key] = self._record()
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
        tmp.replace(self.path)

    def _load(self) -> None:
        assert self.path is not None
        try:
            data = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return
        rec = data.get(self.key) if isinstance(data, dict) else None
        if not isinstance(rec, dict):
            return
        regs = rec.get("registers", {})
        if isinstance(regs, dict):
            for name, value in regs.items():
                reg = yzaim.BY_NAME.get(name)
                if (reg is not None and reg.saved and isinstance(value, int)
                        and not isinstance(value, bool) and reg.valid(value)):
                    self.registers[name] = value
        position = rec.get("position")
        if isinstance(position, int) and not isinstance(position, bool) \
                and yzaim.INT32_MIN <= position <= yzaim.INT32_MAX:
            self.position = position
        saves = rec.get("saves", 0)
        self.saves = saves if isinstance(saves, int) and saves >= 0 else 0
        self.loaded = True
