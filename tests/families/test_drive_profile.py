"""Profile math (servobus.families.dmm.profile) and the ``servobus profile`` command: Appendix B."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from servobus.cli.main import cli
from servobus.families.dmm.profile import pack_arc_word, ptp_profile, unpack_arc_word


def test_appendix_b_example_exact() -> None:
    p = ptp_profile(48, 30, 4096, 140_000)
    assert p.gear_ratio == 1
    assert round(p.speed_rpm) == 1985
    assert round(p.accel_rpm_s) == 19073
    assert p.distance_counts == 560_000
    assert round(p.distance_rev, 3) == 8.545
    assert round(p.accel_time_s, 3) == 0.104
    assert round(p.accel_distance_rev, 2) == 1.72
    assert round(p.cruise_time_s, 3) == 0.154
    assert round(p.trapezoid_time_s, 3) == 0.362
    assert p.trapezoid_time_s < p.total_time_s <= 1.05 * p.trapezoid_time_s


def test_gear_ratio_scales_speed_accel_distance() -> None:
    base, geared = ptp_profile(48, 30, 4096, 1000), ptp_profile(48, 30, 2048, 1000)
    assert geared.speed_rpm == pytest.approx(2 * base.speed_rpm)
    assert geared.accel_rpm_s == pytest.approx(2 * base.accel_rpm_s)
    assert geared.distance_counts == pytest.approx(2 * base.distance_counts)


def test_short_move_is_a_triangle() -> None:
    p = ptp_profile(48, 30, 4096, 500)
    assert p.cruise_time_s == 0
    assert p.peak_speed_rpm < p.speed_rpm
    # area of the triangle = distance
    assert p.peak_speed_rpm / 60 * p.accel_time_s * 65536 == pytest.approx(p.distance_counts)


@pytest.mark.parametrize("plane,feed", [(0, 1), (0, -1), (1, 127), (2, -127), (2, 5)])
def test_arc_word_round_trip(plane: int, feed: int) -> None:
    assert unpack_arc_word(pack_arc_word(plane, feed)) == (plane, feed)


def test_profile_command_prints_appendix_b_table() -> None:
    res = CliRunner().invoke(cli, ["profile", "--max-speed", "48", "--max-accel", "30",
                                   "--gear", "4096", "140000"])
    assert res.exit_code == 0, res.output
    for text in ("1985 rpm", "19073 rpm/s", "560000 counts", "0.104 s", "1.72 rev",
                 "0.154 s", "0.362 s"):
        assert text in res.output


def test_profile_command_json_and_range_check() -> None:
    res = CliRunner().invoke(cli, ["--json", "profile", "140000"])
    assert res.exit_code == 0
    assert json.loads(res.output)["distance_counts"] == 560_000
    bad = CliRunner().invoke(cli, ["profile", "--max-speed", "128", "1"])
    assert bad.exit_code != 0 and "128" in bad.output
