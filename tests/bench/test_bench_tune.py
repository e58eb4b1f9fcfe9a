"""The tune benchmark's verdict is the issue's criterion (benchmarks/bench_tune.py)."""

from __future__ import annotations

from benchmarks.bench_tune import _meets
from servobus.tune.tuner import Trial


def trial(overshoot: float, settling: float | None, vibration: float = 0.0) -> Trial:
    return Trial({}, overshoot, settling, None, None, vibration)


def test_a_case_meets_the_target_only_calm_within_10_percent_and_1_25_x_the_grid() -> None:
    grid = trial(2.0, 0.100)
    assert _meets(trial(10.0, 0.125), grid)
    assert not _meets(trial(10.1, 0.100), grid)  # overshoot
    assert not _meets(trial(1.0, 0.126), grid)  # slower than 1.25 x the grid's best
    assert not _meets(trial(1.0, 0.050, vibration=0.05), grid)  # vibrates
    assert not _meets(trial(1.0, None), grid)  # never settled
    assert not _meets(None, grid)  # aborted
    assert _meets(trial(1.0, 0.5), trial(30.0, None, vibration=0.7))  # no calm grid case
