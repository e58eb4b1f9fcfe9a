"""Step-response figures against closed-form responses (first and second order)."""

from __future__ import annotations

import math

import pytest

from servobus.axis.step_metrics import step_metrics

DT = 1e-4


def record(fn: object, seconds: float, t_cmd: float = 1.0, delay: float = 0.0,
           start: float = 1000.0, step: float = 5000.0) -> tuple[list[float], list[float]]:
    times = [t_cmd - 0.05 + i * DT for i in range(round((seconds + 0.05) / DT))]
    ys = [start + step * (fn(t - t_cmd - delay) if t >= t_cmd + delay else 0.0)  # type: ignore[operator]
          for t in times]
    return times, ys


def test_first_order_step() -> None:
    tau = 0.02
    times, ys = record(lambda t: 1 - math.exp(-t / tau), 0.5)
    m = step_metrics(times, ys, 1.0, 1000.0, 6000.0)
    assert m.rise_time_s == pytest.approx(tau * math.log(9), abs=2 * DT)
    assert m.overshoot_pct == 0.0
    assert m.settling_time_s == pytest.approx(tau * math.log(50), abs=2 * DT)
    assert m.delay_s == pytest.approx(-tau * math.log(0.98), abs=2 * DT)
    assert m.steady_state_error == pytest.approx(0.0, abs=1.0)
    assert m.following_error_max is None and m.peak_time_s is not None


@pytest.mark.parametrize("zeta", [0.3, 0.5, 0.7])
def test_second_order_step_overshoot_and_peak_time(zeta: float) -> None:
    wn = 60.0
    wd = wn * math.sqrt(1 - zeta**2)
    phi = math.acos(zeta)

    def response(t: float) -> float:
        return 1 - math.exp(-zeta * wn * t) / math.sqrt(1 - zeta**2) * math.sin(wd * t + phi)

    times, ys = record(response, 1.0, delay=0.003)
    m = step_metrics(times, ys, 1.0, 1000.0, 6000.0, band=10.0)
    analytic = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    assert m.overshoot_pct == pytest.approx(analytic, abs=0.05)
    assert m.peak_time_s == pytest.approx(0.003 + math.pi / wd, abs=2 * DT)
    assert m.settle_band == 100.0  # 2 % of 5000 counts beats the 10-count window
    envelope_in_band = math.log(1 / (0.02 * math.sqrt(1 - zeta**2))) / (zeta * wn)
    assert m.settling_time_s is not None and m.settling_time_s <= 0.003 + envelope_in_band
    after = [abs(y - 6000.0) for t, y in zip(times, ys, strict=True)
             if t >= 1.0 + m.settling_time_s]
    assert max(after) <= 100.0  # in the band for good from then on
    i = times.index(min(times, key=lambda t: abs(t - (1.0 + m.settling_time_s))))
    assert abs(ys[i - 1] - 6000.0) > 100.0  # ... and not one sample earlier
    assert m.rise_time_s is not None and 0 < m.rise_time_s < m.peak_time_s


def test_negative_step_unsettled_record_and_following_error() -> None:
    times = [0.0, 0.1, 0.2, 0.3, 0.4]
    ys = [0.0, -40.0, -90.0, -120.0, -80.0]  # still swinging when the record ends
    errs = [0.0, 5.0, -12.0, 3.0, float("nan")]
    m = step_metrics(times, ys, 0.0, 0.0, -100.0, position_errors=errs)
    assert m.overshoot_pct == pytest.approx(20.0)
    assert m.settling_time_s is None
    assert m.following_error_max == 12.0
    assert m.rise_time_s == pytest.approx(0.2 - 0.025)


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ValueError):
        step_metrics([0.0], [0.0], 0.0, 5.0, 5.0)  # no step
    with pytest.raises(ValueError):
        step_metrics([0.0, 1.0], [0.0], 0.0, 0.0, 1.0)
    with pytest.raises(ValueError):
        step_metrics([0.0], [0.0], 1.0, 0.0, 1.0)  # nothing after the command
