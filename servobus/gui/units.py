"""Position units the Motion and Tuning panels offer, converted to counts of the axis."""

from __future__ import annotations

from servobus.axis.base import AsyncAxis
from servobus.errors import ArgumentRangeError

UNITS = ("counts", "rev", "deg")


def to_counts(axis: AsyncAxis, value: float, unit: str) -> int:
    """``value`` in ``unit`` -> counts (rev and deg rounded half away from zero)."""
    if unit == "counts":
        if value != int(value):
            raise ArgumentRangeError(f"{value} counts: counts are whole numbers")
        return int(value)
    if unit == "rev":
        return axis.revs(value)
    if unit == "deg":
        return axis.degrees(value)
    raise ArgumentRangeError(f"unit {unit!r}: one of {', '.join(UNITS)}")
