"""``servobus tune`` (servobus.cli.tune_cmd): it asks before moving, refuses a distance
beyond the soft limits before anything moves, and tunes a loaded virtual drive."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_rig import CELL, run
from cli_rig import no_env as no_env

from servobus.axis import connect

LOADED = "sim://dyn232?fast=1&load=direct&inertia=10"


def test_declining_the_question_moves_nothing(capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("sys.stdin", __import__("io").StringIO("n\n"))
    code, out, err = run(capsys, "--url", LOADED, "tune", "--distance", "0.25rev")
    assert code != 0
    assert "tune drive 0" in err and "0.25rev away" in err and "declined" in err
    assert "before" not in out


def test_a_distance_beyond_the_soft_limits_is_refused_before_anything_moves(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    machine = tmp_path / "cell.toml"
    machine.write_text(CELL)
    code, _out, err = run(capsys, "--machine", str(machine), "--axis", "x", "tune",
                         "--distance", "400", "--yes")
    assert code == 2 and "limit" in err.lower()


@pytest.mark.slow  # about 30 s of wall-clock test moves
@pytest.mark.timeout(120)
def test_tune_a_loaded_virtual_drive_and_revert_on_request(
        capsys: pytest.CaptureFixture[str]) -> None:
    # Measured: overshoot 20 - 22 % before, 0.2 - 2 % after, about 45 test moves (the drive
    # learns its load first and the loop is tried softer, docs/tuning.md), 36 EEPROM writes
    # (on simulated time: 45, 36; goal stiffness 32, 36).
    code, out, err = run(capsys, "--url", LOADED, "--json", "tune", "--distance", "0.25rev",
                         "--yes", "--revert")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["before"]["overshoot_pct"] > 15.0
    assert doc["after"]["overshoot_pct"] <= 10.0 and doc["after"]["vibration"] < 0.05
    assert doc["tuned"] != doc["original"] and doc["writes"] <= 40
    assert doc["source"] == "trace" and doc["reverted"] is True
    with connect(LOADED) as axis:  # a fresh virtual drive: the defaults, as kept
        assert {n: axis.read_param(n) for n in doc["original"]} == doc["original"]


def test_save_is_refused_where_the_family_saves_no_other_way(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = run(capsys, "--url", LOADED, "tune", "--distance", "1000", "--save",
                          "--yes")
    assert code == 2 and "EEPROM" in err and "nothing was moved" in err


def test_restore_takes_no_run_options_and_a_run_needs_a_distance(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = run(capsys, "--url", LOADED, "tune", "--restore", "--distance", "1000")
    assert code == 2 and "--restore runs no test moves" in err
    code, _out, err = run(capsys, "--url", LOADED, "tune", "--yes")
    assert code == 2 and "--distance" in err and "--restore" in err
    # an in-process virtual drive ends with its process: nothing is ever recorded for it
    code, _out, err = run(capsys, "--url", LOADED, "tune", "--restore")
    assert code == 2 and "no tuning run is recorded" in err, err
