"""The parameter backup format: round trip, validation with typed errors (no drive needed)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from servobus.errors import ArgumentRangeError
from servobus.families import params_file as PF
from servobus.families.dmm import params as P

SERVOBUS = [sys.executable, "-m", "servobus"]  # the interpreter running the tests


def good_doc() -> dict[str, object]:
    return PF.ParamsBackup("dyn232", 3, {n: P.spec(n).default for n in P.DYN_PARAMS}).to_json()


def write(tmp_path: Path, doc: object) -> Path:
    path = tmp_path / "backup.json"
    path.write_text(json.dumps(doc))
    return path


def test_round_trip(tmp_path: Path) -> None:
    values = {n: P.spec(n).minimum + i for i, n in enumerate(P.DYN_PARAMS)}
    backup = PF.ParamsBackup("dyncan", 7, values)
    PF.save(tmp_path / "b.json", backup)
    assert PF.load(tmp_path / "b.json") == backup
    doc = json.loads((tmp_path / "b.json").read_text())
    assert doc["format"] == PF.FORMAT and doc["version"] == PF.VERSION


def test_subset_and_unknown_top_level_keys_are_accepted(tmp_path: Path) -> None:
    doc = good_doc() | {"comment": "tuned for the X axis", "params": {"main_gain": 90}}
    assert PF.load(write(tmp_path, doc)).params == {"main_gain": 90}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"format": "other"}, "format"),
        ({"version": 2}, "newer"),
        ({"version": "1"}, "version"),
        ({"protocol": 5}, "protocol"),
        ({"family": "acme"}, "family"),
        ({"drive_id": 256}, "drive_id"),
        ({"drive_id": True}, "drive_id"),
        ({"params": {}}, "non-empty"),
        ({"params": {"main_gian": 40}}, "unknown parameter 'main_gian'"),
        ({"params": {"main_gain": 40.5}}, "integer"),
        ({"params": {"main_gain": True}}, "integer"),
    ],
)
def test_format_errors(tmp_path: Path, change: dict[str, object], message: str) -> None:
    with pytest.raises(PF.ParamsFileError, match=message):
        PF.load(write(tmp_path, good_doc() | change))


@pytest.mark.parametrize(("name", "value"), [("main_gain", 0), ("main_gain", 128),
                                             ("gear_num", 499), ("gear_num", 16385)])
def test_out_of_range_values_are_refused(tmp_path: Path, name: str, value: int) -> None:
    with pytest.raises(ArgumentRangeError, match=f"{name}={value}"):
        PF.load(write(tmp_path, good_doc() | {"params": {name: value}}))


def test_not_json_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    with pytest.raises(PF.ParamsFileError, match="not JSON"):
        PF.load(bad)
    with pytest.raises(PF.ParamsFileError, match="cannot read"):
        PF.load(tmp_path / "missing.json")


def test_diff() -> None:
    assert PF.diff({"main_gain": 40, "gear_num": 4096}, {"main_gain": 41, "gear_num": 4096}) == [
        ("main_gain", 40, 41)]


@pytest.mark.slow  # a real process
def test_cli_load_validates_before_connecting(tmp_path: Path) -> None:
    # --port points nowhere: the file error must come first, as a typed error, exit 2.
    path = write(tmp_path, good_doc() | {"params": {"gear_num": 20000}})
    proc = subprocess.run([*SERVOBUS, "--port", "socket://127.0.0.1:9", "params", "--load",
                           str(path)], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert proc.stderr.startswith(f"error: {path}: gear_num=20000 is outside the allowed range "
                                  "500..16384")
    assert "cannot open" not in proc.stderr  # the file was refused before connecting


@pytest.mark.slow  # a real process
def test_cli_set_checks_range_before_connecting() -> None:
    proc = subprocess.run([*SERVOBUS, "--port", "socket://127.0.0.1:9", "set", "main_gain", "0"],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert proc.stderr.startswith("error: main_gain=0 is outside the allowed range 1..127")
