"""The machine file (TOML, docs/machine.md): names, links, units, limits of every axis.

Parsing is pure (no link is opened) and every mistake is one :class:`MachineFileError`
line naming the file, the axis and the key: ``m.toml: axis x: limits: ...``.

Decisions (docs/machine.md): ``per_rev`` is the travel of one revolution of the driven side
(after the gear); ``gear`` is motor revolutions per driven revolution (10 for a 10:1
reducer); ``direction = -1`` flips the sign between user units and counts. Limits count
from the drive's origin. Unknown keys are mistakes (a typo must not silently drop a limit).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from servobus.axis.url import parse_url
from servobus.errors import ArgumentRangeError, MachineFileError

UNITS = ("mm", "deg", "rev", "counts")
#: per_rev when the file gives none: a degree axis turns 360 deg per revolution, ...
DEFAULT_PER_REV: Mapping[str, float] = {"deg": 360.0, "rev": 1.0}
ORIGINS = ("none", "set", "home")
#: What ``servobus hal`` does with the axis (docs/linuxcnc.md): read and report only, or
#: stream LinuxCNC's position command to the drive.
HAL_MODES = ("monitor", "position")
NAME = re.compile(r"^[A-Za-z0-9_-]+$")
AXIS_KEYS = frozenset({"url", "id", "unit", "per_rev", "gear", "direction", "limits", "speed",
                       "accel", "origin", "label", "continuous", "hal"})
TOP_KEYS = frozenset({"name", "axes"})


@dataclass(frozen=True)
class AxisSpec:
    """One ``[axes.NAME]`` table, checked."""

    name: str
    url: str
    drive_id: int | None  # None: the protocol's default id
    unit: str  # "mm" | "deg" | "rev" | "counts"
    per_rev: float | None  # user units per driven revolution (None on a counts axis)
    gear: float = 1.0  # motor revolutions per driven revolution
    direction: int = 1  # +1 or -1
    limits: tuple[float, float] | None = None
    speed: float | None = None  # default speed, user units per second
    accel: float | None = None  # user units per second squared (documented, see docs)
    origin: str = "none"  # "none" | "set" | "home"
    label: str = ""  # free text for people (GUI tooltip)
    #: The axis may turn for ever (a spindle, a conveyor): only then is constant speed
    #: open-ended (docs/safety.md). Allowed only on an axis without limits.
    continuous: bool = False
    #: ``servobus hal``'s mode for the axis: "monitor" (report only) or "position".
    hal: str = "monitor"


@dataclass(frozen=True)
class MachineSpec:
    name: str
    path: Path | None
    axes: tuple[AxisSpec, ...]


class _Where:
    """Builds the one-line errors of one file (and axis)."""

    def __init__(self, source: str, axis: str | None = None) -> None:
        self.source = source
        self.axis = axis

    def error(self, key: str | None, message: str) -> MachineFileError:
        parts = [self.source]
        if self.axis is not None:
            parts.append(f"axis {self.axis}")
        if key is not None:
            parts.append(key)
        return MachineFileError(": ".join(parts) + ": " + " ".join(message.split()))


def load_machine_file(path: str | Path) -> MachineSpec:
    """Read and check ``path``; MachineFileError (one line) on any mistake."""
    p = Path(path)
    where = _Where(str(p))
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise where.error(None, f"cannot read the machine file ({exc.strerror or exc})") \
            from None
    except UnicodeDecodeError:
        raise where.error(None, "not UTF-8 text") from None
    return parse_machine(text, source=str(p), path=p)


def parse_machine(text: str, *, source: str = "<machine>", path: Path | None = None,
                  ) -> MachineSpec:
    """Parse machine-file text (``source`` names it in errors)."""
    where = _Where(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise where.error(None, f"not valid TOML ({exc})") from None
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise where.error(unknown[0], f"unknown key; a machine file has: "
                          f"{', '.join(sorted(TOP_KEYS))}")
    name = data.get("name", path.stem if path is not None else "machine")
    if not isinstance(name, str) or not name.strip():
        raise where.error("name", f"must be a non-empty string, got {name!r}")
    axes_table = data.get("axes")
    if not isinstance(axes_table, dict) or not axes_table:
        raise where.error("axes", "the file names no axis; add e.g. [axes.x] with url = ...")
    axes: list[AxisSpec] = []
    for axis_name, table in axes_table.items():
        axes.append(_axis(_Where(source, axis_name), axis_name, table))
    _check_shared_ids(where, axes)
    return MachineSpec(name=name, path=path, axes=tuple(axes))


def _check_shared_ids(where: _Where, axes: list[AxisSpec]) -> None:
    seen: dict[tuple[str, int | None], str] = {}
    for spec in axes:
        key = (link_key(spec.url), spec.drive_id)  # `h:4001` and `h:4001/` are one drive
        if key in seen:
            raise _Where(where.source, spec.name).error(
                "id", f"{spec.url} id {spec.drive_id if spec.drive_id is not None else 'default'}"
                f" is already axis {seen[key]}; two axes cannot be one drive")
        seen[key] = spec.name


def link_key(url: str) -> str:
    """One key for the spellings of one link (DriveUrl.link_key); the URL itself when it
    does not parse (its own check names the mistake)."""
    try:
        return parse_url(url).link_key
    except ArgumentRangeError:
        return url


def _number(where: _Where, key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise where.error(key, f"must be a finite number, got {value!r}")
    return float(value)


def _positive(where: _Where, key: str, value: object) -> float:
    number = _number(where, key, value)
    if number <= 0:
        raise where.error(key, f"must be > 0, got {value!r}")
    return number


def _axis(where: _Where, name: str, table: object) -> AxisSpec:
    if not NAME.match(name):
        raise where.error(None, "axis names are letters, digits, _ and - only")
    if not isinstance(table, dict):
        raise where.error(None, f"must be a table ([axes.{name}]), got {table!r}")
    unknown = sorted(set(table) - AXIS_KEYS)
    if unknown:
        raise where.error(unknown[0], f"unknown key; an axis has: {', '.join(sorted(AXIS_KEYS))}")
    url = table.get("url")
    if not isinstance(url, str) or not url.strip():
        raise where.error("url", "missing: every axis names its drive URL (url = \"...\")")
    drive_id = table.get("id")
    if drive_id is not None and (isinstance(drive_id, bool) or not isinstance(drive_id, int)
                                 or not 0 <= drive_id <= 255):
        raise where.error("id", f"must be an integer 0..255, got {drive_id!r}")
    unit = table.get("unit", "counts")
    if unit not in UNITS:
        raise where.error("unit", f"must be one of {', '.join(UNITS)}, got {unit!r}")
    per_rev: float | None
    if "per_rev" in table:
        if unit == "counts":
            raise where.error("per_rev", "a counts axis has no per_rev (counts are the "
                              "drive's own); set unit = \"mm\", \"deg\" or \"rev\"")
        per_rev = _positive(where, "per_rev", table["per_rev"])
    elif unit == "mm":
        raise where.error("per_rev", "missing: a mm axis needs the travel per revolution "
                          "(per_rev = 5.0 for a 5 mm lead screw)")
    else:
        per_rev = DEFAULT_PER_REV.get(unit)
    gear = _positive(where, "gear", table.get("gear", 1.0))
    if unit == "counts" and gear != 1.0:
        raise where.error("gear", "a counts axis counts at the motor; no gear")
    direction = table.get("direction", 1)
    if direction not in (1, -1) or isinstance(direction, bool):
        raise where.error("direction", f"must be 1 or -1, got {direction!r}")
    limits = _limits(where, table.get("limits"))
    speed = None if "speed" not in table else _positive(where, "speed", table["speed"])
    accel = None if "accel" not in table else _positive(where, "accel", table["accel"])
    origin = table.get("origin", "none")
    if origin not in ORIGINS:
        raise where.error("origin", f"must be one of {', '.join(ORIGINS)}, got {origin!r}")
    label = table.get("label", "")
    if not isinstance(label, str):
        raise where.error("label", f"must be a string, got {label!r}")
    continuous = table.get("continuous", False)
    if not isinstance(continuous, bool):
        raise where.error("continuous", f"must be true or false, got {continuous!r}")
    continuous = continuous or url_continuous(url)
    hal = table.get("hal", "monitor")
    if hal not in HAL_MODES:
        raise where.error("hal", f"must be one of {', '.join(HAL_MODES)}, got {hal!r}")
    if hal == "position" and (speed is None or accel is None):
        raise where.error("hal", "a position axis needs speed and accel: servobus hal refuses "
                          "a command step beyond them")
    if continuous and limits is not None:
        raise where.error("continuous", "an axis that turns for ever has no soft limits; "
                          "remove limits or continuous")
    return AxisSpec(name=name, url=url.strip(), drive_id=drive_id, unit=unit, per_rev=per_rev,
                    gear=gear, direction=int(direction), limits=limits, speed=speed,
                    accel=accel, origin=origin, label=label, continuous=continuous,
                    hal=hal)


def url_continuous(url: str) -> bool:
    """``?continuous=1`` (or true/yes) on a drive URL; a malformed URL is the opener's to
    report, so it reads as not continuous here."""
    try:
        raw = parse_url(url).option("continuous", "0") or "0"
    except ArgumentRangeError:
        return False
    return raw.strip().lower() in ("1", "true", "yes")


def url_spec(url: str, drive_ids: Sequence[int | None] = (None,), *,
             name: str = "drive") -> MachineSpec:
    """A bare drive URL as a machine (issue 27: one path for motion, limits and leases):
    one axis per id, named by its id (``axis`` for the protocol's default id), in counts,
    without limits; ``continuous`` as the URL's ``?continuous=`` says."""
    axes = tuple(AxisSpec(name="axis" if i is None else str(i), url=url, drive_id=i,
                          unit="counts", per_rev=None, continuous=url_continuous(url))
                 for i in drive_ids)
    if not axes:
        raise ArgumentRangeError("a drive URL as a machine needs at least one id")
    return MachineSpec(name=name, path=None, axes=axes)


def _limits(where: _Where, value: object) -> tuple[float, float] | None:
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 2:
        raise where.error("limits", f"must be [low, high] in the axis's unit, got {value!r}")
    low, high = (_number(where, "limits", v) for v in value)
    if not low < high:
        raise where.error("limits", f"low must be below high, got [{low:g}, {high:g}]")
    return low, high
