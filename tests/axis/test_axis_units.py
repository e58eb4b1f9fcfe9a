"""servobus.axis.units: the one drive-unit conversion the CLI, the GUI and Family use."""

from __future__ import annotations

import math

import pytest

from servobus.axis.units import DRIVE_UNITS, from_counts, round_counts, to_counts
from servobus.errors import ArgumentRangeError
from servobus.families import family


def test_drive_units_to_counts() -> None:
    assert to_counts(16384, "counts", 65536) == 16384
    assert to_counts(2.5, "rev", 65536) == 163840
    assert to_counts(-90, "deg", 65536) == -16384
    assert to_counts(36, "deg", 32768) == round(32768 / 10)


def test_back_to_the_unit() -> None:
    assert from_counts(163840, "rev", 65536) == 2.5
    assert from_counts(-16384, "deg", 65536) == -90.0
    assert from_counts(7, "counts", 65536) == 7.0


@pytest.mark.parametrize("value, unit", [(1.5, "counts"), (math.inf, "counts"),
                                         (math.nan, "rev"), (1.0, "mm"), (1.0, "")])
def test_refused(value: float, unit: str) -> None:
    with pytest.raises(ArgumentRangeError):
        to_counts(value, unit, 65536)


def test_half_away_from_zero() -> None:
    assert (round_counts(0.5), round_counts(-0.5), round_counts(1.49)) == (1, -1, 1)


def test_the_family_converts_through_it() -> None:
    dyn2 = family("dmm-dyn2")
    assert dyn2.revs_to_counts(0.3) == to_counts(0.3, "rev", dyn2.counts_per_rev)
    assert dyn2.degrees_to_counts(33.3) == to_counts(33.3, "deg", dyn2.counts_per_rev)
    assert DRIVE_UNITS == ("counts", "rev", "deg")
