"""benchmarks plant's arithmetic: the figure from the line through (axis samples/s, CPU %),
and the machine file it serves (benchmarks/bench_plant.py)."""

from __future__ import annotations

import tomllib

import pytest

from benchmarks.bench_plant import RATE_HZ, figure, fit, machine_toml, per_half_core


def test_the_figure_is_where_the_line_through_the_runs_reaches_half_a_core() -> None:
    # 2 % of upkeep and 300 us per axis sample: 50 % at 1,600 samples/s, 32 axes at 50 Hz
    points = [(axes * RATE_HZ, 2.0 + axes * RATE_HZ * 300e-6 * 100) for axes in (16, 32, 48)]
    base, slope = fit(points)
    assert base == pytest.approx(2.0) and slope * 1e4 == pytest.approx(300.0)
    assert per_half_core(points) == pytest.approx(32.0)


def test_the_machine_puts_per_link_drives_on_each_link() -> None:
    urls = ["dyn232+socket://127.0.0.1:1", "dyncan+socketcand://127.0.0.1:2",
            "easycan+socketcand://127.0.0.1:3"]
    machine = tomllib.loads(machine_toml("plant-12", urls, per_link=4))
    axes = machine["axes"]
    assert len(axes) == 12
    for url in urls:
        ids = sorted(a["id"] for a in axes.values() if a["url"] == url)
        assert ids == [1, 2, 3, 4]
    assert all(a["unit"] == "deg" for a in axes.values() if a["url"].startswith("easycan"))


def _run(axes: int, hz: float, load: float = 1.0) -> dict[str, float]:
    samples = axes * hz  # 2 % of upkeep and 300 us per axis sample, as above
    return {"count": axes, "hz": hz, "samples": samples, "cpu": 2.0 + samples * 300e-4,
            "load": load}


def test_the_figure_comes_only_from_runs_whose_links_reached_45_hz() -> None:
    # a run under 45 Hz, however cheap its samples look, is left out of the line
    slow = {**_run(48, 20.0), "cpu": 5.0}
    line = figure([_run(8, 50.0, 0.5), _run(16, 46.0, 0.9), slow], "2 drives per link")
    assert "axes per half core at 50 Hz: 32 " in line
    assert "runs of 8, 16 axes" in line and "300 us per axis sample" in line
    assert "2 drives per link; load average 0.5 - 0.9" in line
    assert "beyond the largest run" in line
    assert "no figure" in figure([_run(8, 50.0), slow], "")
    assert "within the runs measured" in figure([_run(16, 50.0), _run(40, 50.0)], "")
