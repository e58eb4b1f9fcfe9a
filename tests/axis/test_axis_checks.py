"""checks.positive: a physical quantity (not seconds) refused with its own unit in the message."""

from __future__ import annotations

import math

import pytest

from servobus import checks
from servobus.errors import ArgumentRangeError


@pytest.mark.parametrize("bad", [0, -1.5, math.nan, math.inf, True, "20", None])
def test_positive_refuses_and_names_the_unit(bad: object) -> None:
    with pytest.raises(ArgumentRangeError, match=r"peak_current_a=.* number of A > 0"):
        checks.positive("peak_current_a", bad, "A")


def test_positive_takes_a_finite_positive_number() -> None:
    assert checks.positive("peak_current_a", 20, "A") == 20.0
