"""The parameter backup file of ``servobus params --save/--load/--diff`` and of the GUI
(pure, no drive I/O). A family-level format: the family's table validates every value, so
it sits below the front ends that read and write it.

Format (JSON, UTF-8), version 1::

    {
      "format": "servobus.params",
      "version": 1,
      "protocol": "dyn232",            # protocol of the drive it was read from
      "family": "dmm-dyn2",            # device family: its table validates the values
      "drive_id": 1,
      "saved": "2025-01-31T12:00:00+00:00",
      "params": {"main_gain": 40, "speed_gain": 40, ...}
    }

Decisions: parameter names are the snake_case names of the family's table (the same on every
protocol, so a DYN232M backup restores onto a DYN CAN drive: ``--load``/``--diff`` name both
protocols in a note, and refuse a file whose parameters the protocol cannot reach or whose
family differs from the drive's, naming both); a file without ``family`` is a
DMM DYN2 backup (what servobus wrote before families existed); a file may hold a
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
from servobus.families import family

FORMAT = "servobus.params"
VERSION = 1
#: Version-1 files name no family: their protocols were DMM DYN2's.
V1_FAMILY = "dmm-dyn2"
MAX_DRIVE_ID = 255


class ParamsFileError(ServobusError):
    """A parameter backup file is unreadable or not in the servobus.params format."""


@dataclass(frozen=True)
class ParamsBackup:
    protocol: str
    drive_id: int
    params: dict[str, int]
    family: str = V1_FAMILY
    saved: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))
    version: int = VERSION

    def to_json(self) -> dict[str, object]:
        return {
            "format": FORMAT,
            "version": self.version,
            "protocol": self.protocol,
            "family": self.family,
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
    if "format" not in doc:
        raise ParamsFileError(f"{where}: not a servobus parameter backup (it has no "
                              f"\"format\": \"{FORMAT}\" field)")
    if doc["format"] != FORMAT:
        raise ParamsFileError(f"{where}: format is {doc['format']!r}, expected {FORMAT!r}")
    version = doc.get("version")
    if not _is_int(version) or version < 1:
        raise ParamsFileError(f"{where}: version {_given(version)} is not a positive integer")
    if version > VERSION:
        raise ParamsFileError(f"{where}: version {version} is newer than this servobus "
                              f"understands ({VERSION})")
    protocol = doc.get("protocol")
    if not isinstance(protocol, str) or not protocol:
        raise ParamsFileError(f"{where}: protocol {_given(protocol)} is not a protocol name")
    family_name = doc.get("family", V1_FAMILY)
    try:
        fam = family(str(family_name))
    except ArgumentRangeError as exc:
        raise ParamsFileError(f"{where}: {exc}") from None
    drive_id = doc.get("drive_id")
    if not _is_int(drive_id) or not 0 <= drive_id <= MAX_DRIVE_ID:
        raise ParamsFileError(f"{where}: drive_id {_given(drive_id)} is not 0..{MAX_DRIVE_ID}")
    raw = doc.get("params")
    if not isinstance(raw, dict) or not raw:
        raise ParamsFileError(f"{where}: 'params' must be a non-empty object")
    params: dict[str, int] = {}
    known = {p.name: p for p in fam.params}
    for name, value in raw.items():
        if name not in known:
            raise ParamsFileError(f"{where}: unknown parameter {name!r}; "
                                  f"known: {', '.join(known)}")
        if not _is_int(value):
            raise ParamsFileError(f"{where}: {name} must be an integer, got {_given(value)}")
        try:
            params[name] = known[name].check(value)
        except ArgumentRangeError as exc:
            raise ArgumentRangeError(f"{where}: {exc}") from None
    saved = doc.get("saved", "")
    return ParamsBackup(protocol, drive_id, params, fam.name, str(saved), version)


def diff(wanted: Mapping[str, int], actual: Mapping[str, int]) -> list[tuple[str, int, int]]:
    """(name, wanted, actual) for every parameter of ``wanted`` whose value differs."""
    return [(n, v, actual[n]) for n, v in wanted.items() if actual.get(n) != v]


def _given(value: object) -> str:
    """A field's value for a message: ``missing`` rather than Python's ``None``."""
    return "missing" if value is None else repr(value)


def _is_int(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)
