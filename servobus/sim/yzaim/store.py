"""EEPROM of a virtual YZ-AIM motor: the saved registers, the recorded position, write count.

The motor writes it only when the host sets the save flag 0x14 (manual 5.2) - every saved
register at once - and records its position at power-off (1: "communication mode: power-off
record position"). With a path it is kept as JSON so it survives a restart of the simulator
(``servobus sim easycan --state FILE``, ``sim modbus --state FILE``, ``sim://easycan?state=``).
Several motors may share one file: each keeps its own record under the address it had when
the record was made (its serial number).

The file is the virtual drives' state file (:class:`servobus.sim.core.state_file.StateFile`,
one machinery for every family): checked whole at start-up, locked against a second
simulator, written atomically, every other motor's record kept when one motor rewrites its
own.

File format (decision): ``{"<address 1..254>": {"registers": {name: raw value}, "position":
counts or null, "saves": n}}``; every field optional. Decision (issue 17, replacing "a record
that cannot be read is ignored"): anything the motor could not have stored - a file that is not
JSON, a record that is not an object, an unknown field, a register that is not a saved register
of the family table or is out of its range, a position outside int32, a negative save count -
refuses the start with one line naming the file and the problem, and the file is left as it
was: running on defaults would silently drop that motor's record at the next save.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from servobus.families.yzaim import registers as yzaim
from servobus.sim.core.state_file import RecordStore, StateKind, checked_int, describe

_FIELDS = frozenset({"registers", "position", "saves"})
_ADDRESS = yzaim.BY_NAME["device_address"]


def check_yzaim_record(key: str, rec: object) -> dict[str, Any]:
    """One motor's record, normalised; ValueError names the first problem."""
    if not (key.isdigit() and key == str(int(key))
            and _ADDRESS.minimum <= int(key) <= _ADDRESS.maximum):
        raise ValueError(f"the key must be a device address {_ADDRESS.minimum}.."
                         f"{_ADDRESS.maximum}")
    if not isinstance(rec, dict):
        raise ValueError(f"must be an object, got {describe(rec)}")
    unknown = sorted(set(rec) - _FIELDS)
    if unknown:
        raise ValueError(f"unknown field {unknown[0]!r}")
    registers = rec.get("registers", {})
    if not isinstance(registers, dict):
        raise ValueError(f"registers must be an object, got {describe(registers)}")
    checked: dict[str, int] = {}
    for name, value in registers.items():
        reg = yzaim.BY_NAME.get(name)
        if reg is None or not reg.saved:
            raise ValueError(f"{name!r} is not a saved register")
        checked[name] = checked_int(value, name, reg.minimum, reg.maximum)
        if value in reg.invalid:
            raise ValueError(f"{name} {value} is not a value the motor defines")
    position = rec.get("position")
    if position is not None:
        checked_int(position, "position", yzaim.INT32_MIN, yzaim.INT32_MAX)
    saves = checked_int(rec.get("saves", 0), "saves", 0, 1 << 62)
    return {"registers": checked, "position": position, "saves": saves}


YZAIM_STATE = StateKind("motor records", check_yzaim_record)


class YzaimStore(RecordStore):
    def __init__(self, path: str | Path | None = None, key: str = "1") -> None:
        self.registers: dict[str, int] = {
            r.name: r.default for r in yzaim.SAVED if r.default is not None}
        self.position: int | None = None  # counts recorded at the last power-off
        self.saves = 0
        self.loaded = False
        super().__init__(path, key, YZAIM_STATE)

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

    def _restore(self, rec: dict[str, Any]) -> None:
        self.registers.update(rec["registers"])
        self.position = rec["position"]
        self.saves = rec["saves"]
        self.loaded = True
