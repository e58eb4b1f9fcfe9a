"""The position command's checks against the machine file's speed and accel."""

from __future__ import annotations

import pytest

from servobus.hal.step_guard import JOIN_S, SLACK_S, WINDOW_S, StepGuard, StepRefused


def joined(speed: float = 100.0, accel: float = 1000.0) -> StepGuard:
    guard = StepGuard(speed, accel, "deg")
    guard.join(0.0, 0.0, 0.0)
    return guard


def test_a_ramp_within_speed_and_accel_is_accepted() -> None:
    guard = joined()
    t, x = 0.0, 0.0
    for _ in range(200):  # 50 deg/s reached at 500 deg/s^2, then held
        t += 0.002
        x += min(50.0, 500.0 * t) * 0.002
        guard.check(t, x)
    assert x > 10.0


def test_a_step_beyond_speed_is_refused_naming_it() -> None:
    guard = joined()
    with pytest.raises(StepRefused, match="above speed 100 deg/s"):
        guard.check(0.01, 100.0 * (0.01 + SLACK_S) + 0.5)


def test_a_speed_jump_beyond_accel_is_refused() -> None:
    guard = joined(speed=1000.0, accel=100.0)
    guard.check(WINDOW_S, 0.0)  # standing for one window
    with pytest.raises(StepRefused, match="above accel 100 deg/s"):
        guard.check(2 * WINDOW_S, 500.0 * WINDOW_S)  # 500 deg/s at once


def test_the_first_command_stands_near_the_motor() -> None:
    guard = StepGuard(100.0, 1000.0, "deg")
    guard.join(0.0, 10.0 + 100.0 * JOIN_S * 0.9, 10.0)
    with pytest.raises(StepRefused, match="from the motor at enable"):
        StepGuard(100.0, 1000.0, "deg").join(0.0, 10.0 + 100.0 * JOIN_S * 1.1, 10.0)


def test_nothing_is_accepted_before_enable() -> None:
    with pytest.raises(StepRefused, match="since enable"):
        StepGuard(100.0, 1000.0).check(0.0, 0.0)
