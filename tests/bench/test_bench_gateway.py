"""benchmarks gateway's per-sample figure: the CPU share over the samples the links
actually took, not over the asked 32 x 50 (benchmarks/bench_gateway.py)."""

from __future__ import annotations

import math

import pytest

from benchmarks.bench_gateway import AXES, LINKS, RATE_HZ, per_sample_us, samples_taken


def test_samples_taken_are_each_links_rate_times_its_axes() -> None:
    rates = {f"link{i}": hz for i, hz in enumerate((6.0, 14.0, 15.0, 7.0))}
    assert samples_taken(rates) == pytest.approx(42.0 * AXES / len(LINKS))
    every_link_at_rate = {f"link{i}": RATE_HZ for i in range(len(LINKS))}
    assert samples_taken(every_link_at_rate) == pytest.approx(AXES * RATE_HZ)


def test_the_cost_per_sample_counts_the_samples_taken() -> None:
    # half a core over 320 samples/s is 1,562.5 us a sample, not 312.5 as over 1,600
    assert per_sample_us(0.5, 320.0) == pytest.approx(1562.5)
    assert per_sample_us(0.5, AXES * RATE_HZ) == pytest.approx(312.5)
    assert math.isinf(per_sample_us(0.5, 0.0))
