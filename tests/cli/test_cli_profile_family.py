"""``servobus profile`` asks the named drive's Family for its point-to-point table
(Family.ptp_profile): the DMM families have one, YZ-AIM none; ranges are that family's."""

from __future__ import annotations

import json

from click.testing import CliRunner

from servobus.cli.main import cli
from servobus.errors import NotSupported
from servobus.families import family


def test_the_defaults_are_the_family_parameters() -> None:
    dyn2 = family("dmm-dyn2")
    res = CliRunner().invoke(cli, ["--json", "profile", "1000"])
    assert res.exit_code == 0, res.output
    table = json.loads(res.output)
    assert {k: table[k] for k in ("max_speed", "max_accel", "gear_num")} == {
        n: dyn2.param(n).default for n in ("max_speed", "max_accel", "gear_num")}


def test_the_dyn5_has_the_same_table() -> None:
    res = CliRunner().invoke(cli, ["--url", "sim://enip", "--json", "profile", "140000"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["distance_counts"] == 560_000


def test_a_family_without_a_table_says_so() -> None:
    res = CliRunner().invoke(cli, ["--url", "sim://easycan", "profile", "1000"])
    assert isinstance(res.exception, NotSupported)
    assert "no point-to-point profile table" in str(res.exception)
    assert family("yzaim").ptp_profile is None
