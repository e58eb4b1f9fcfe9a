"""User units <-> the Axis's counts (counts per revolution from the drive family).

``counts = user x counts_per_rev x gear / per_rev x direction``; a counts axis is the
Axis's own counts (times ``direction``). Never a protocol's raw units: the Axis already
turns counts into what its wire carries (DMM's GEAR_NUM included). Speeds in user units
per second; the Axis's rpm are motor revolutions per minute.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from servobus.axis.units import round_counts
from servobus.errors import InvalidValue

_QUANTITY = re.compile(r"^([-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[-+]?\d+)?)\s*([a-z]*)$")
_ALIASES = {"": "", "count": "counts", "counts": "counts", "mm": "mm", "deg": "deg",
            "rev": "rev", "revs": "rev"}


@dataclass(frozen=True)
class Scale:
    """How one machine axis's user unit maps onto its drive's counts."""

    unit: str
    counts_per_rev: int
    per_rev: float | None = None  # user units per driven revolution; None on a counts axis
    gear: float = 1.0
    direction: int = 1

    @property
    def counts_per_unit(self) -> float:
        if self.per_rev is None:
            return float(self.direction)
        return self.counts_per_rev * self.gear / self.per_rev * self.direction

    def to_counts(self, user: float) -> int:
        """User units -> counts (rounded half away from zero; NaN/inf refused)."""
        return round_counts(float(user) * self.counts_per_unit)

    def to_user(self, counts: float) -> float:
        return counts / self.counts_per_unit

    def to_rpm(self, user_per_s: float) -> float:
        """User units per second -> motor rpm (signed as the Axis's)."""
        return user_per_s * self.counts_per_unit / self.counts_per_rev * 60.0

    def from_rpm(self, rpm: float) -> float:
        return rpm * self.counts_per_rev / 60.0 / self.counts_per_unit


_SPEED = re.compile(r"^([-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[-+]?\d+)?)\s*([a-z]*)(?:/s)?$")


def parse_speed(text: str, unit: str, *, axis: str = "") -> float:
    """``"20"`` / ``"20mm"`` / ``"20mm/s"`` -> 20.0, in ``unit`` per second: a speed in any
    other unit (``30deg`` on a mm axis, ``nan``) is one InvalidValue line naming the axis's."""
    match = _SPEED.match(str(text).strip().lower())
    if match is None or match.group(2) not in ("", unit):
        where = f"axis {axis}'s " if axis else "the axis's "
        raise InvalidValue(f"{text!r}: a speed is in {where}{unit}/s, e.g. 20 or 20{unit}")
    return float(match.group(1))


def parse_quantity(text: str, unit: str, *, axis: str = "") -> tuple[float, str]:
    """``"12.5"`` / ``"12.5mm"`` / ``"100counts"`` -> (number, unit) on an axis of ``unit``.

    A bare number is in the axis's unit; a number with another user unit (``12.5mm`` on a
    ``deg`` axis) is one ArgumentRangeError line. ``counts`` is always accepted (whole).
    """
    where = f"axis {axis} " if axis else ""
    match = _QUANTITY.match(str(text).strip().lower())
    written = _ALIASES.get(match.group(2)) if match else None
    if match is None or written is None:
        raise InvalidValue(f"{text!r}: write a number in {where}units ({unit}), e.g. "
                                 f"12.5 or 12.5{unit if unit != 'counts' else ''}")
    number = float(match.group(1))
    given = written or unit
    if given == "counts":
        if not number.is_integer():
            raise InvalidValue(f"{text!r}: counts are whole numbers")
        return number, "counts"
    if given != unit:
        raise InvalidValue(f"{text!r}: {where}is in {unit}, not {given}; give "
                                 f"{number:g}{unit if unit != 'counts' else ''} or counts")
    return number, given
