"""The CLI on a machine file, in-process (servobus.cli.main.main: exit code and one line)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from machine_rig import Run, write_machine
from machine_rig import run as run  # the fixture, for this module

import servobus.machine.links as links
from servobus.axis.base import AsyncAxis
from servobus.transport.base import Direction


@pytest.fixture
def sent(monkeypatch: pytest.MonkeyPatch) -> list[object]:
    """What every link the machine opens sends, through the Axis trace hook."""
    frames: list[object] = []
    real = links.connect_async

    async def traced(url: str | None = None, **kw: Any) -> AsyncAxis:
        axis = await real(url, **kw)
        await axis.add_trace(lambda d, data, t: frames.append(data)
                             if d is Direction.TX else None)
        return axis

    monkeypatch.setattr(links, "connect_async", traced)
    return frames


def test_move_in_mm_ends_at_the_right_count(run: Run, tmp_path: Path, sent: list[object]) -> None:
    m = str(write_machine(tmp_path))
    code, out, err = run("--machine", m, "--axis", "x", "--json", "move", "12.5mm", "--wait")
    assert code == 0, err
    doc = json.loads(out)
    assert abs(doc["counts"] - 163840) <= 64 and abs(doc["position"] - 12.5) < 0.01
    assert sent  # the move went out
    code, out, _ = run("--machine", m, "--axis", "x", "move", "12.5", "--wait")
    # a bare number is in the axis's unit; the drive settles within its window (as above)
    done = re.search(r"done at (-?[0-9.]+) mm \((-?\d+) counts\)", out)
    assert code == 0 and done is not None, out
    assert abs(float(done.group(1)) - 12.5) < 0.01 and abs(int(done.group(2)) - 163840) <= 64


def test_a_move_past_the_limit_is_refused_before_the_wire(
        run: Run, tmp_path: Path, sent: list[object]) -> None:
    m = str(write_machine(tmp_path))
    code, out, err = run("--machine", m, "--axis", "x", "move", "300.5")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "outside the soft limits [-10, 300] mm" in err
    assert sent == []
    code, _, err = run("--machine", m, "--axis", "c", "move", "12.5mm")
    assert code == 2 and err.count("\n") == 1 and "axis c is in deg, not mm" in err
    assert sent == []


def test_one_axis_command_without_axis_lists_the_names(run: Run, tmp_path: Path) -> None:
    m = str(write_machine(tmp_path))
    code, _, err = run("--machine", m, "move", "1")
    assert code == 2 and err.count("\n") == 1 and "has axes x, y, c: give --axis NAME" in err
    code, _, err = run("--machine", m, "--axis", "q", "position")
    assert code == 2 and "no axis 'q'" in err and "axes: x, y, c" in err


def test_status_lists_every_axis_in_one_table(run: Run, tmp_path: Path) -> None:
    m = str(write_machine(tmp_path))
    code, out, err = run("--machine", m, "status")
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0] == "machine test-cell" and lines[1].split()[:3] == ["axis", "position",
                                                                       "counts"]
    assert [line.split()[0] for line in lines[2:]] == ["x", "y", "c"]
    assert "(easycan)" in out and "(dyn232)" in out
    code, out, _ = run("--machine", m, "--json", "status")
    doc = json.loads(out)
    assert [a["axis"] for a in doc["axes"]] == ["x", "y", "c"]
    assert {a["unit"] for a in doc["axes"]} == {"mm", "deg"}


def test_position_json_gives_unit_and_counts(run: Run, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SERVOBUS_MACHINE", str(write_machine(tmp_path)))
    code, out, err = run("--axis", "c", "position", "--json")
    assert code == 0, err
    assert json.loads(out) == {"axis": "c", "position": 0.0, "unit": "deg", "counts": 0}


def test_a_mistake_in_the_file_is_one_line(run: Run, tmp_path: Path) -> None:
    m = str(write_machine(tmp_path, '[axes.x]\nurl = "sim://"\nunit = "mm"\n'))
    code, _, err = run("--machine", m, "status")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"error: {m}: axis x: per_rev: missing")


def test_axis_without_a_file_uses_the_builtin_machine(run: Run) -> None:
    code, out, err = run("--axis", "y", "--json", "move", "20", "--wait")
    assert code == 0, err
    assert abs(json.loads(out)["position"] - 20.0) < 0.01
    code, _, err = run("--url", "sim://", "--axis", "y", "position")
    assert code == 2 and "--axis y names an axis of a machine file" in err


def test_speed_on_a_limited_axis_stops_at_the_limit(run: Run, tmp_path: Path) -> None:
    text = ('[axes.c]\nurl = "sim://easycan?fast=1"\nid = 1\nunit = "deg"\n'
            "limits = [-10.0, 90.0]\n")
    code, out, err = run("--machine", str(write_machine(tmp_path, text)), "--json", "speed",
                         "360")
    assert code == 0, err
    doc = json.loads(out)
    # Issue 27: the held speed's targets never pass the limit, so the motor rests at it
    # (within the drive's in-position window, +-10 counts = 0.11 deg), not past it after a
    # watcher's stop as before (the old test allowed up to 120 deg).
    assert doc["unit"] == "deg/s" and doc["ended"] == "limit"
    assert abs(doc["stopped_at"] - 90.0) <= 0.11, doc


def test_params_reach_the_axis_of_the_machine(run: Run, tmp_path: Path) -> None:
    code, out, err = run("--machine", str(write_machine(tmp_path)), "--axis", "c", "--json",
                         "params")
    assert code == 0, err
    doc = json.loads(out)
    assert (doc["family"], doc["drive_id"]) == ("yzaim", 1)  # the c axis answered
    assert "target_speed" in doc["params"]


def test_status_marks_an_unreachable_link_offline_and_exits_2(run: Run, tmp_path: Path) -> None:
    import machine_rig

    from servobus.axis import registry

    registry.register("flaky", "machine_rig:flaky_open")
    machine_rig.FLAKY.update(down=True, attempts=0)
    text = machine_rig.MIXED + '\n[axes.z]\nurl = "flaky://line"\nid = 3\nunit = "rev"\n'
    m = str(write_machine(tmp_path, text))
    code, out, err = run("--machine", m, "status")
    assert code == 2 and err.count("\n") == 1 and "axes offline: z" in err
    row = next(line for line in out.splitlines() if line.startswith("z "))
    assert "flaky://line id 3 OFFLINE" in row
    assert [line.split()[0] for line in out.splitlines()[2:]] == ["x", "y", "c", "z"]
    code, _, err = run("--machine", m, "--axis", "z", "position")
    assert code == 2 and "axis z: cannot open flaky://line" in err
