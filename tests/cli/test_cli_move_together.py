"""Issue 32: ``move --together`` and the machine file's speed/accel in ``move`` (in-process).

``--together`` starts the axes by one trigger where their drives share a synchronised start
(two DYN CAN drives on one bus), else one after another, and says what the start skew can
be. ``move`` sets the drive's profile from the file's ``speed``/``accel`` before moving,
writing only what differs: a virtual drive's state file (its EEPROM, with write counters)
shows each parameter written once over two commands, and a refused move writes nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_rig import no_env as no_env  # the fixture, for this module
from cli_rig import run

from servobus.cli import failures as F
from servobus.cli.together_cmd import SYNCED, UNSYNCED
from servobus.families.dmm import units as U

CAN_PAIR = """\
[axes.a]
url = "sim://dyncan?fast=1"
id = 1
unit = "rev"

[axes.b]
url = "sim://dyncan?fast=1"
id = 2
unit = "rev"
"""




def machine(tmp_path: Path, text: str) -> str:
    path = tmp_path / "m.toml"
    path.write_text(text, encoding="utf-8")
    return str(path)


# ------------------------------------------------------------------ --together
def test_axes_of_two_links_start_one_after_another_and_reach_their_targets(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "--json", "move", "--together", "x=10", "c=90deg", "--wait")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["targets"] == {"x": 10.0, "c": 90.0} and doc["units"] == {"x": "mm", "c": "deg"}
    assert doc["synchronised"] is False and doc["groups"] == [] and doc["skew_note"] == UNSYNCED
    assert doc["skew_ms"] == max(doc["start_offsets_ms"].values()) >= 0.0
    assert abs(doc["positions"]["x"] - 10.0) < 0.01 and abs(doc["positions"]["c"] - 90.0) < 0.1
    code, out, err = run(capsys, "move", "--together", "x=10", "y=20")
    assert code == 0, err
    assert out.startswith("moving together: x to 10 mm, y to 20 mm\nstart skew ")
    assert " ms measured at the host: " in out and "at least this" in out


def test_drives_with_a_synchronised_start_start_by_one_trigger(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    m = machine(tmp_path, CAN_PAIR)
    code, out, err = run(capsys, "--machine", m, "--json", "move", "--together", "a=1",
                         "b=-0.5", "--wait")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["synchronised"] is True and doc["groups"] == [["a", "b"]]
    assert doc["skew_ms"] == 0.0 and doc["skew_note"] == SYNCED
    assert abs(doc["positions"]["a"] - 1.0) < 0.001 and abs(doc["positions"]["b"] + 0.5) < 0.001
    code, out, err = run(capsys, "--machine", m, "move", "--together", "a=0", "b=0")
    assert code == 0, err
    assert out.splitlines()[1] == f"start: a, b {SYNCED}"


@pytest.mark.parametrize(("args", "words"), [
    (("--url", "sim://dyn232?fast=1", "move", "--together", "x=1"), "not a drive URL"),
    (("--axis", "x", "move", "--together", "x=1"), "drop --axis"),
    (("move", "--together", "--relative", "x=1"), "drop --relative"),
    (("move", "--together", "x"), "NAME=TARGET pairs"),
    (("move", "--together", "x=1", "x=2"), "axis x is named twice"),
    (("move", "--together", "z=1"), "no axis 'z'"),
    (("move", "--together", "x=1000"), "outside the soft limits"),
    (("move", "--together", "c=5mm"), "is in deg, not mm"),
])
def test_a_together_move_that_cannot_be_is_one_line_and_sends_nothing(
        capsys: pytest.CaptureFixture[str], args: tuple[str, ...], words: str) -> None:
    code, out, err = run(capsys, *args)
    assert code == F.EXIT_USAGE and out == ""
    assert words in err and err.startswith("error: ") and err.count("\n") == 1


# ------------------------------------------------------------------ speed/accel of the file
def test_move_writes_the_files_profile_once_and_only_what_differs(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    state = tmp_path / "eeprom.json"
    m = machine(tmp_path, f"""\
[axes.x]
url = "sim://dyn232?fast=1&state={state}"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]
speed = 50.0     # 10 rev/s = 600 rpm
accel = 500.0    # 100 rev/s^2 = 6000 rpm/s
""")
    expected = U.profile_params(600.0, 6000.0, 4096)
    assert expected == {"max_speed": 26, "max_accel": 9}
    code, out, err = run(capsys, "--machine", m, "--axis", "x", "move", "400")  # refused
    assert code == F.EXIT_USAGE and "soft limits" in err
    assert "max_speed" not in json.loads(state.read_text()).get("1", {}).get("writes", {})
    code, out, err = run(capsys, "--machine", m, "--axis", "x", "--json", "move", "5", "--wait")
    assert code == 0, err
    assert json.loads(out)["profile_written"] == expected
    assert "note: axis x: the drive's move profile now follows the machine file's" in err
    assert "max_speed = 26, max_accel = 9" in err
    code, out, err = run(capsys, "--machine", m, "--axis", "x", "--json", "move", "0", "--wait")
    assert code == 0, err
    assert "profile_written" not in json.loads(out) and "move profile" not in err
    record = json.loads(state.read_text())["1"]
    assert {k: record["params"][k] for k in expected} == expected
    assert record["writes"]["max_speed"] == record["writes"]["max_accel"] == 1


def test_the_files_speed_is_a_yzaim_motors_cruise_speed(capsys: pytest.CaptureFixture[str],
                                                         tmp_path: Path) -> None:
    m = machine(tmp_path, """\
[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
speed = 720.0    # 2 rev/s = 120 rpm
""")
    code, out, err = run(capsys, "--machine", m, "--axis", "c", "--json", "move", "30", "--wait")
    assert code == 0, err
    assert json.loads(out)["profile_written"] == {"target_speed": 120}
