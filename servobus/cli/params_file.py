"""The parameter backup file of ``servobus params --save/--load/--diff`` (pure, no drive I/O).

Format (JSON, UTF-8), version 1::

    {
      "format": "servobus.params",
      "version": 1,
      "protocol": "dyn232",            # protocol of the drive it was read from
      "drive_id": 1,
      "saved": "2025-01-31T12:00:00+00:00",
      "params": {"main_gain": 40, "speed_gain": 40, ...}
    }

Decisions: parameter names are the snake_case names of ``servobus.families.dmm.params`` (the same
on every protocol, so a DYN232M backup restores onto a DYN CAN drive); a file may hold a
subset of the parameters (only those are restored); unknown top-level keys are ignored so a
later minor addition stays readable; a higher ``version`` is refused. Every value is checked
against the parameter table on load, so an out-of-range value never reaches a drive.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TypeGuard

from servobus.errors import ArgumentRangeError, ServobusError
from servobus.families.dmm import params as P
from servobus.protocols.dyn232.codec import MAX_DRIVE_ID

FORMAT = "servobus.params"
VERSION = 1
PROTOCOLS = ("dyn232", "dyncan")


class ParamsFileError(ServobusError):
    """A parameter backup file is unreadable or not in the servobus.params format."""


@dataclass(frozen=True)
class ParamsBackup:
    protocol: str
    drive_id: int
    params: dict[str, int]
    saved: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))
    version: int = VERSION

    def to_json(self) -> dict[str, object]:
        return {
            "format": FORMAT,
            "version": self.version,
            "protocol": self.protocol,
            "drive_id": self.drive_id,
            "saved": self.saved,
            "params": dict(self.params),
        }


def save(path: str | Path, backup: ParamsBackup) -> None:
    text = json.dumps(backup.to_json(), indent=2) + "\n"
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise ParamsFileError(f"cannot write {path}: {exc}") from None


def load(path: str | Path) -> ParamsBackup:
    """Read and validate a backup; ParamsFileError for format problems, ArgumentRangeError for
    values outside the parameter table's ranges."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ParamsFileError(f"cannot read {path}: {exc}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParamsFileError(f"{path} is not JSON: {exc}") from None
    return parse(doc, str(path))


def parse(doc: object, where: str = "backup") -> ParamsBackup:
    if not isinstance(doc, dict):
        raise ParamsFileError(f"{where}: expected a JSON object")
    if doc.get("format") != FORMAT:
        raise ParamsFileError(f"{where}: format is {doc.get('format')!r}, expected {FORMAT!r}")
    version = doc.get("version")
    if not _is_int(version) or version < 1:
        raise ParamsFileError(f"{where}: version {version!r} is not a positive integer")
    if version > VERSION:
        raise ParamsFileError(f"{where}: version {version} is newer than this servobus "
                              f"understands ({VERSION})")
    protocol = doc.get("protocol")
    if protocol not in PROTOCOLS:
        raise ParamsFileError(f"{where}: protocol {protocol!r} is not one of {PROTOCOLS}")
    drive_id = doc.get("drive_id")
    if not _is_int(drive_id) or not 0 <= drive_id <= MAX_DRIVE_ID:
        raise ParamsFileError(f"{where}: drive_id {drive_id!r} is not 0..{MAX_DRIVE_ID}")
    raw = doc.get("params")
    if not isinstance(raw, dict) or not raw:
        raise ParamsFileError(f"{where}: 'params' must be a non-empty object")
    params: dict[str, int] = {}
    for name, value in raw.items():
        if name not in P.BY_NAME:
            raise ParamsFileError(f"{where}: unknown parameter {name!r}; "
                                  f"known: {', '.join(P.BY_NAME)}")
        if not _is_int(value):
            raise ParamsFileError(f"{where}: {name} must be an integer, got {value!r}")
        try:
            params[name] = P.spec(name).check(value)
        except ArgumentRangeError as exc:
            raise ArgumentRangeError(f"{where}: {exc}") from None
    saved = doc.get("saved", "")
    return ParamsBackup(str(protocol), drive_id, params, str(saved), version)


def diff(wanted: Mapping[str, int], actual: Mapping[str, int]) -> list[tuple[str, int, int]]:
    """(name, wanted, actual) for every parameter of ``wanted`` whose value differs."""
    return [(n, v, actual[n]) for n, v in wanted.items() if actual.get(n) != v]


def _is_int(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)
