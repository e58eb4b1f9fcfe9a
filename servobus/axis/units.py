"""A drive's own position units - counts, revolutions, degrees - and counts, once.

The CLI (``servobus move 2.5rev``), the GUI (the Motion and Tuning panels' unit) and the
Family (``revs_to_counts``) all convert through here, so a TARGET means the same counts in
every front end. A machine axis's user units (mm, its gear and direction) are
``servobus.machine.units.Scale``, on top of these counts.
"""

from __future__ import annotations

import math

from servobus.errors import InvalidValue

#: The position units of a bare drive, in the order the front ends offer them.
DRIVE_UNITS = ("counts", "rev", "deg")
#: Units of ``unit`` in one revolution, for the units that are fractions of a turn.
PER_REV = {"rev": 1.0, "deg": 360.0}


def round_counts(value: float) -> int:
    """Round half away from zero; NaN and infinities are refused."""
    if not math.isfinite(value):
        raise InvalidValue(f"a position must be a finite number, got {value!r}")
    return int(math.copysign(math.floor(abs(value) + 0.5), value))


def check_unit(unit: str) -> str:
    """``unit`` when it is one of :data:`DRIVE_UNITS`; ArgumentRangeError naming them."""
    if unit not in DRIVE_UNITS:
        raise InvalidValue(f"unit {unit!r}: one of {', '.join(DRIVE_UNITS)}")
    return unit


def to_counts(value: float, unit: str, counts_per_rev: int) -> int:
    """``value`` in ``unit`` -> counts (rev and deg rounded half away from zero; counts
    must be whole)."""
    if check_unit(unit) == "counts":
        if not math.isfinite(value) or value != int(value):
            raise InvalidValue(f"{value} counts: counts are whole numbers")
        return int(value)
    return round_counts(value / PER_REV[unit] * counts_per_rev)


def from_counts(counts: float, unit: str, counts_per_rev: int) -> float:
    """Counts -> ``unit`` (not rounded: the caller formats)."""
    if check_unit(unit) == "counts":
        return float(counts)
    return counts / counts_per_rev * PER_REV[unit]
