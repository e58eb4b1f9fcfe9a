"""Issue 32, the commands a DMMDRV user reaches for (in-process, virtual drives): ``enable``,
``disable``, ``origin``, ``home`` on one drive and on a machine axis, and the following
error in ``status``.

Each command runs on a fresh virtual drive; what the drive is before the command (disabled,
off its zero, in absolute mode, in alarm) is set by an action run on every Axis the CLI
opens (the ``on_connect`` fixture).
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest
from cli_rig import CELL, run
from cli_rig import no_env as no_env  # the fixture, for this module
from cli_rig import on_connect as on_connect  # the fixture

from servobus.axis.base import AsyncAxis
from servobus.axis.types import AxisStatus
from servobus.cli import failures as F
from servobus.families.dmm.registers import DriveConfig

Action = Callable[[AsyncAxis], Awaitable[None]]
URLS = ["sim://dyn232?fast=1", "sim://easycan?fast=1", "sim://enip"]





async def disabled(ax: AsyncAxis) -> None:
    await ax.disable()


async def one_rev_off(ax: AsyncAxis) -> None:
    await ax.move_by(ax.revs(1), wait=True)


async def absolute_off_zero(ax: AsyncAxis) -> None:
    """A DMM drive in absolute mode whose stored zero is here, then 0.3 rev away from it."""
    await ax.set_config(DriveConfig(absolute=True))  # type: ignore[attr-defined]
    await ax.set_origin()
    await ax.move_by(ax.revs(0.3), wait=True)


async def alarmed(ax: AsyncAxis) -> None:
    """The drive reports a latched alarm and takes no enable (as a DMM drive in alarm)."""
    real = ax.status
    code = 0x14 if ax.family.name == "yzaim" else 2

    async def status() -> AxisStatus:
        st = await real()
        return dataclasses.replace(st, alarm_code=code, alarm_text=ax.family.alarm_text(code),
                                   alarm_latched=True, enabled=False)

    async def refuse() -> None:
        return None

    ax.status = status  # type: ignore[method-assign]
    ax.enable = refuse  # type: ignore[method-assign]


# ------------------------------------------------------------------ enable, disable
@pytest.mark.parametrize("url", URLS)
def test_disable_then_enable_report_what_the_drive_shows(
        capsys: pytest.CaptureFixture[str], on_connect: list[Action], url: str) -> None:
    code, out, err = run(capsys, "--url", url, "--id", "1", "--json", "disable")
    assert code == 0, err
    assert json.loads(out) == {"drive_id": 1, "enabled": False}
    on_connect.append(disabled)  # the next drive starts disabled: enable has work to do
    code, out, err = run(capsys, "--url", url, "--id", "1", "enable")
    assert code == 0, err
    assert out == "drive 1 enabled (servo on)\n"


def test_enable_of_a_drive_in_alarm_exits_1_and_names_the_alarm(
        capsys: pytest.CaptureFixture[str], on_connect: list[Action]) -> None:
    on_connect.append(alarmed)
    code, out, err = run(capsys, "--url", "sim://dyn232?fast=1", "enable",
                         "--wait-timeout", "0.2")
    assert code == F.EXIT_FAULT
    assert "drive 0 did not enable: alarm 2" in err and "(latched)" in err
    assert "`servobus reset`" in err and err.count("\n") == 1
    assert "disabled (motor free)" in out  # what the drive shows, before the error


@pytest.mark.parametrize("axis", ["x", "c"])
def test_enable_and_disable_a_machine_axis(capsys: pytest.CaptureFixture[str],
                                           on_connect: list[Action], tmp_path: Path,
                                           axis: str) -> None:
    machine = tmp_path / "m.toml"
    machine.write_text(CELL, encoding="utf-8")
    on_connect.append(disabled)
    code, out, err = run(capsys, "--machine", str(machine), "--axis", axis, "enable")
    assert code == 0, err
    assert out == f"axis {axis} enabled (servo on)\n"
    code, out, err = run(capsys, "--machine", str(machine), "--axis", axis, "--json",
                         "disable")
    assert code == 0, err
    assert json.loads(out) == {"axis": axis, "enabled": False}


# ------------------------------------------------------------------ origin
@pytest.mark.parametrize("url", URLS)
def test_origin_makes_where_the_motor_stands_zero(
        capsys: pytest.CaptureFixture[str], on_connect: list[Action], url: str) -> None:
    on_connect.append(one_rev_off)
    code, out, err = run(capsys, "--url", url, "--id", "1", "--json", "origin")
    assert code == 0, err
    doc = json.loads(out)
    per_rev = 32_768 if "easycan" in url else 65_536
    assert abs(doc["position_before"] - per_rev) <= 50, doc  # one revolution off
    assert abs(doc["position"]) <= 50 and doc["unit"] == "counts" and doc["origin_set"]


def test_origin_on_a_machine_axis_counts_the_limits_from_it(
        capsys: pytest.CaptureFixture[str], on_connect: list[Action], tmp_path: Path) -> None:
    machine = tmp_path / "m.toml"
    machine.write_text(CELL, encoding="utf-8")
    on_connect.append(one_rev_off)
    code, out, err = run(capsys, "--machine", str(machine), "--axis", "x", "origin")
    assert code == 0, err
    match = re.fullmatch(r"axis x: origin set where it stands \(it read (\S+) mm, now (\S+) "
                         r"mm\); the soft limits count from it\n", out)
    assert match is not None, out
    before, now = (float(v) for v in match.groups())
    assert abs(before - 5.0) < 0.01 and abs(now) < 0.01  # one revolution of a 5 mm screw


# ------------------------------------------------------------------ home
@pytest.mark.parametrize(("url", "why"), [
    ("sim://dyn232?fast=1", "is in relative mode (config b2 = 0): a DMM DYN2/DC2/DYN4 homes "
                            "only in absolute mode"),
    ("sim://enip", "a DMM DYN5 runs no homing of its own"),
    ("sim://easycan?fast=1", "a YZ-AIM motor homes only by itself at power-on"),
])
def test_home_says_why_where_the_drive_has_no_homing(capsys: pytest.CaptureFixture[str],
                                                     url: str, why: str) -> None:
    code, out, err = run(capsys, "--url", url, "home")
    assert code == F.EXIT_USAGE and out == ""
    assert err.startswith("error: ") and why in err and err.count("\n") == 1
    assert "nothing was sent" in err and "origin" in err


@pytest.mark.parametrize("url", ["sim://dyn232?fast=1", "sim://dyncan?fast=1"])
def test_home_returns_a_dmm_drive_in_absolute_mode_to_its_stored_zero(
        capsys: pytest.CaptureFixture[str], on_connect: list[Action], url: str) -> None:
    on_connect.append(absolute_off_zero)
    code, out, err = run(capsys, "--url", url, "--id", "1", "--json", "home")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["homed"] is True and abs(doc["position"]) <= 50, doc  # 0.3 rev = 19,661


def test_home_on_a_machine_axis(capsys: pytest.CaptureFixture[str], on_connect: list[Action],
                                tmp_path: Path) -> None:
    machine = tmp_path / "m.toml"
    machine.write_text(CELL, encoding="utf-8")
    on_connect.append(absolute_off_zero)
    code, out, err = run(capsys, "--machine", str(machine), "--axis", "x", "home")
    assert code == 0, err
    assert out.startswith("axis x: homed, at ") and out.rstrip().endswith(" mm")
    assert abs(float(out.split("at ")[1].split()[0])) < 0.01


# ------------------------------------------------------------------ following error
@pytest.mark.parametrize(("url", "reported"), [("sim://dyn232?fast=1", True),
                                               ("sim://easycan?fast=1", False)])
def test_status_shows_the_following_error_where_the_drive_reports_it(
        capsys: pytest.CaptureFixture[str], url: str, reported: bool) -> None:
    code, out, err = run(capsys, "--url", url, "--json", "status")
    assert code == 0, err
    error = json.loads(out)["following_error"]
    assert isinstance(error, float) if reported else error is None
    code, out, err = run(capsys, "--url", url, "status")
    line = next(row for row in out.splitlines() if row.strip().startswith("following_error"))
    assert line.endswith(" counts") if reported else line.endswith("not reported by this drive")


def test_machine_status_has_a_following_error_column(capsys: pytest.CaptureFixture[str],
                                                     tmp_path: Path) -> None:
    machine = tmp_path / "m.toml"
    machine.write_text(CELL, encoding="utf-8")
    code, out, err = run(capsys, "--machine", str(machine), "status")
    assert code == 0, err
    head, x, c = out.splitlines()[1:4]
    cells = head.split()
    assert cells[:7] == ["axis", "position", "counts", "enabled", "moving", "in_pos", "f_error"]
    assert x.split()[7] == "0.0000" and c.split()[7] == "-"  # the YZ-AIM reports none
    code, out, err = run(capsys, "--machine", str(machine), "--json", "status")
    errors = {a["axis"]: a["following_error"] for a in json.loads(out)["axes"]}
    assert errors == {"x": 0.0, "c": None}
