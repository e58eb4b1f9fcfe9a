"""The scope's pure logic on synthetic signals: ring, min/max decimation, trigger, frames."""

from __future__ import annotations

import math
from array import array

import pytest

from servobus.gui import frames
from servobus.gui.decimate import (
    RollingDecimator,
    bucket_count,
    decimate_window,
    use_pairs,
)
from servobus.gui.ring import SampleRing
from servobus.gui.trigger import (
    Edge,
    TriggerSettings,
    TriggerTracker,
    crossing_time,
    find_crossing,
)

RATE = 4000.0


def fill(ring: SampleRing, fn: object, t0: float, seconds: float, rate: float = RATE,
         name: str = "position") -> None:
    n = round(seconds * rate)
    times = [t0 + i / rate for i in range(n)]
    ring.extend(times, {name: array("d", (fn(t) for t in times))})  # type: ignore[operator]


# ------------------------------------------------------------------ ring
def test_ring_keeps_absolute_indices_when_it_drops_old_samples() -> None:
    ring = SampleRing(100)
    for i in range(1000):
        ring.append(float(i), {"position": float(i) * 2})
    assert ring.end == 1000
    assert 100 <= len(ring) <= 150 and ring.base == 1000 - len(ring)
    assert ring.value("position", 999) == 1998.0
    assert ring.index_at(995.0) == 995 and ring.index_at(1e9) == 1000
    assert math.isnan(ring.value("speed", 999))  # never given: NaN
    assert list(ring.column("position", 990, 2000)) == [2.0 * i for i in range(990, 1000)]
    assert list(ring.column("position", 0, 3)) == []  # dropped long ago


def test_ring_refuses_ragged_columns() -> None:
    with pytest.raises(ValueError):
        SampleRing(10).extend([0.0, 1.0], {"position": [1.0]})


# ------------------------------------------------------------------ decimation
def test_bucket_count_and_pairs_follow_the_data_density() -> None:
    assert bucket_count(10.0, 4000, 1000) == 1000  # 40 samples per pixel: one bucket each
    assert use_pairs(10.0, 4000, 1000)
    assert bucket_count(0.05, 4000, 1000) == 200  # 200 samples: one bucket per sample
    assert not use_pairs(0.05, 4000, 200)
    assert bucket_count(1.0, 3.0, 1000) == 16  # very sparse: a floor of 16


def test_min_max_decimation_keeps_a_one_sample_spike_and_the_envelope() -> None:
    ring = SampleRing(100_000)
    fill(ring, lambda t: math.sin(2 * math.pi * 5 * t), 100.0, 2.0)
    spike_t = 101.2345
    i = ring.index_at(spike_t)
    ring.data["position"][i - ring.base] = 7.0  # one sample of 8000
    d = decimate_window(ring, ["position"], 100.0, 102.0, 500, True, t_ref=100.0)
    y = d.ys["position"]
    assert len(d.x) == len(y) == 1000 and d.pairs and d.raw_count == 8000
    assert max(y) == 7.0  # a spike narrower than a pixel is still drawn
    assert min(y) == pytest.approx(-1.0, abs=1e-3)
    k = y.index(7.0)
    assert abs(d.x[k] - (spike_t - 100.0)) <= 2.0 / 500  # within its bucket
    assert list(d.x) == sorted(d.x)


def test_min_and_max_come_in_the_order_they_occurred() -> None:
    ring = SampleRing(10_000)
    fill(ring, lambda t: t, 0.0, 1.0)  # a ramp: min first in every bucket
    up = decimate_window(ring, ["position"], 0.0, 1.0, 100, True, t_ref=0.0).ys["position"]
    assert list(up) == sorted(up)
    ring2 = SampleRing(10_000)
    fill(ring2, lambda t: -t, 0.0, 1.0)
    down = decimate_window(ring2, ["position"], 0.0, 1.0, 100, True, t_ref=0.0).ys["position"]
    assert list(down) == sorted(down, reverse=True)


def test_sparse_data_holds_the_last_value_and_is_nan_before_the_first() -> None:
    ring = SampleRing(100)
    for t, v in ((0.5, 1.0), (0.9, 2.0)):
        ring.append(t, {"speed": v})
    d = decimate_window(ring, ["speed"], 0.0, 1.0, 10, False, t_ref=0.0)
    y = list(d.ys["speed"])
    assert all(math.isnan(v) for v in y[:5])
    assert y[5:9] == [1.0] * 4 and y[9] == 2.0
    assert d.x[0] == pytest.approx(0.05) and not d.pairs


def test_rolling_decimator_matches_a_one_shot_reduction() -> None:
    ring = SampleRing(100_000)
    dt = 0.01
    roll = RollingDecimator(ring, ["position"], dt, True, keep=100)

    def signal(t: float) -> float:
        return math.sin(7 * t) + (3.0 if 2.004 < t < 2.0043 else 0.0)

    for chunk in range(30):  # 3 s arriving in 100 ms chunks (no sample on a bucket edge)
        fill(ring, signal, chunk * 0.1 + 0.5 / RATE, 0.1)
        roll.update()
    k1 = roll.k_next
    assert k1 is not None
    cols = roll.window(k1 - 100, k1)
    once = decimate_window(ring, ["position"], (k1 - 100) * dt, k1 * dt, 100, True, t_ref=0.0)
    a = once.ys["position"][0::2]
    b = once.ys["position"][1::2]
    assert list(cols.a["position"]) == pytest.approx(list(a))
    assert list(cols.b["position"]) == pytest.approx(list(b))
    assert max(cols.b["position"] + cols.a["position"]) > 3.5  # the spike survived


def test_rolling_window_before_the_data_is_nan() -> None:
    ring = SampleRing(1000)
    fill(ring, lambda t: 1.0, 10.0, 0.1)
    roll = RollingDecimator(ring, ["position"], 0.01, False, keep=5)
    k1 = roll.update()
    assert k1 is not None
    cols = roll.window(k1 - 20, k1)
    values = list(cols.a["position"])
    assert len(values) == 20 and all(math.isnan(v) for v in values[:10])
    assert values[-5:] == [1.0] * 5


# ------------------------------------------------------------------ trigger
def test_find_crossing_rising_falling_either() -> None:
    v = [0.0, 1.0, 2.0, 1.0, 0.0, 1.0]
    assert find_crossing(v, 1.5, Edge.RISING) == 2
    assert find_crossing(v, 1.5, Edge.FALLING) == 3
    assert find_crossing(v, 0.5, Edge.EITHER, start=2) == 4
    assert find_crossing(v, 1.0, Edge.RISING) == 1  # reaching the level counts
    assert find_crossing(v, 5.0, Edge.RISING) is None
    assert find_crossing([math.nan, 3.0], 1.0, Edge.RISING) is None
    assert crossing_time(0.0, 0.0, 1.0, 2.0, 0.5) == 0.25


@pytest.mark.parametrize("edge,phase", [(Edge.RISING, 0.0), (Edge.FALLING, 0.5)])
def test_trigger_finds_each_period_of_a_sine_at_the_interpolated_time(edge: Edge,
                                                                      phase: float) -> None:
    ring = SampleRing(200_000)
    settings = TriggerSettings(mode="normal", edge=edge, level=0.0, pre=0.25, window_s=0.2)
    tracker = TriggerTracker(settings, ring, "position")
    hz = 2.0  # period 0.5 s > window: every period triggers
    found = []
    for chunk in range(40):  # 4 s in 0.1 s chunks, sample grid unrelated to the period
        fill(ring, lambda t: math.sin(2 * math.pi * hz * t + 0.3), 0.0123 + chunk * 0.1, 0.1)
        t = tracker.poll()
        while t is not None:
            found.append(t)
            t = tracker.poll()
    end = 0.0123 + 4.0 - settings.post_s
    expected = [t for k in range(10)
                if 0.0123 < (t := (k + phase) / hz - 0.3 / (2 * math.pi * hz)) <= end]
    assert len(expected) >= 7
    assert found == pytest.approx(expected, abs=1e-4)  # interpolated, far below 1/4000 s
    for t in found:  # each returned only once its post-trigger part was recorded
        assert ring.last_time is not None and ring.last_time >= t + settings.post_s


def test_trigger_hold_off_skips_crossings_inside_the_window() -> None:
    ring = SampleRing(200_000)
    settings = TriggerSettings(mode="normal", level=0.0, pre=0.0, window_s=1.0)
    tracker = TriggerTracker(settings, ring, "position")
    fill(ring, lambda t: math.sin(2 * math.pi * 10 * t + 0.1), 0.0, 3.0)  # 10 Hz
    times = []
    while (t := tracker.poll()) is not None:
        times.append(t)
    assert len(times) == 2 and times[1] - times[0] >= 1.0  # the 2nd is after the 1st window


def test_single_mode_captures_once_then_holds_until_rearmed() -> None:
    ring = SampleRing(100_000)
    tracker = TriggerTracker(TriggerSettings(mode="single", level=0.5, window_s=0.1),
                             ring, "moving")
    fill(ring, lambda t: float(int(t * 10) % 2), 0.0, 2.0, name="moving")  # 5 Hz square
    assert tracker.poll() is not None
    fill(ring, lambda t: float(int(t * 10) % 2), 2.0, 2.0, name="moving")
    assert tracker.poll() is None and tracker.done
    tracker.rearm()
    fill(ring, lambda t: float(int(t * 10) % 2), 4.0, 1.0, name="moving")
    assert tracker.poll() is not None


def test_roll_mode_never_triggers_and_settings_are_checked() -> None:
    ring = SampleRing(1000)
    tracker = TriggerTracker(TriggerSettings(mode="roll"), ring, "position")
    fill(ring, lambda t: math.sin(50 * t), 0.0, 0.2)
    assert tracker.poll() is None
    for bad in ({"mode": "free"}, {"pre": 1.5}, {"window_s": 0.0}, {"level": math.inf}):
        with pytest.raises(ValueError):
            TriggerSettings(**bad)  # type: ignore[arg-type]


# ------------------------------------------------------------------ frames
def test_frame_round_trip_and_layout() -> None:
    f = frames.ScopeFrame(t_ref=123.5, rate_hz=4000.0, seq=7, raw_count=40000, newest=-0.001,
                          sent=124.0, flags=frames.FLAG_TRIGGERED | frames.FLAG_PAIRS,
                          x=[-0.1, 0.0, 0.1], ys=[[1.0, 2.0, 3.0], [0.5, math.nan, -1.0]])
    data = f.encode()
    assert len(data) == 48 + 3 * 8 + 2 * 3 * 4
    assert data[:4] == bytes([1, 1, 2, frames.FLAG_TRIGGERED | frames.FLAG_PAIRS])
    g = frames.decode(data)
    assert (g.t_ref, g.rate_hz, g.seq, g.raw_count, g.flags) == (123.5, 4000.0, 7, 40000, 5)
    assert list(g.x) == [-0.1, 0.0, 0.1] and list(g.ys[0]) == [1.0, 2.0, 3.0]
    assert math.isnan(g.ys[1][1])
    with pytest.raises(ValueError):
        frames.decode(data[:-1])
    with pytest.raises(ValueError):
        frames.ScopeFrame(0, 0, 0, 0, 0, 0, 0, [0.0], [[1.0, 2.0]]).encode()
