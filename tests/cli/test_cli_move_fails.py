"""A move that did not end where it was asked says so (issue 28), in-process: ``move --wait``
and ``--confirm`` exit 1 with a typed error on a disabled drive (nothing sent), in alarm, or
stopped off its target, on one drive and on a machine axis alike; ``--machine ... status``
exits 1 when an axis shown is in alarm.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from cli_rig import no_env as no_env  # the fixture, for this module
from cli_rig import on_connect as on_connect  # the fixture
from cli_rig import run

from servobus.axis.base import AsyncAxis
from servobus.axis.types import AxisStatus
from servobus.cli import arrival
from servobus.cli import failures as F
from servobus.cli.arrival import check_arrival, wait_arrival
from servobus.errors import MoveFailed

URLS = ["sim://dyn232?fast=1", "sim://dyncan?fast=1", "sim://easycan?fast=1", "sim://enip",
        "sim://modbus?fast=1"]
LATCHED = {"dmm-dyn2": 2, "dmm-dyn5": 2, "yzaim": 0x14}
OFF = 117_701  # counts from the target, as the issue saw it
MACHINE = """\
[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]

[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
limits = [-720.0, 720.0]
"""


def write_machine(tmp_path: Path) -> Path:
    path = tmp_path / "m.toml"
    path.write_text(MACHINE, encoding="utf-8")
    return path





sent: list[object] = []  # the move primitives called after ``disabled``


async def disabled(ax: AsyncAxis) -> None:
    """The drive disabled; every move primitive it is asked for afterwards is recorded."""
    await ax.disable()
    sent.clear()
    real_to, real_by = ax._send_move_to, ax._send_move_by

    async def send_to(position: int) -> None:
        sent.append(("to", position))
        await real_to(position)

    async def send_by(distance: int) -> None:
        sent.append(("by", distance))
        await real_by(distance)

    ax._send_move_to = send_to  # type: ignore[method-assign]
    ax._send_move_by = send_by  # type: ignore[method-assign]


async def alarmed(ax: AsyncAxis) -> None:
    real = ax.status
    code = LATCHED[ax.family.name]

    async def status() -> AxisStatus:
        st = await real()
        return dataclasses.replace(st, alarm_code=code, alarm_text=ax.family.alarm_text(code),
                                   alarm_latched=True, enabled=False)

    ax.status = status  # type: ignore[method-assign]


async def stops_off_target(ax: AsyncAxis) -> None:
    """Once a move is sent, the drive says idle at once and the position reads OFF counts
    further than the drive is (a motor stopped short by another program, a blocked axis)."""
    real_send, real_position, real_status = ax._send_move_to, ax.position, ax.status
    state = {"sent": False}

    async def send(position: int) -> None:
        await real_send(position)
        state["sent"] = True

    async def position() -> int:
        return await real_position() + (OFF if state["sent"] else 0)

    async def status() -> AxisStatus:
        st = await real_status()
        return dataclasses.replace(st, moving=False, in_position=True) if state["sent"] else st

    ax._send_move_to = send  # type: ignore[method-assign]
    ax.position = position  # type: ignore[method-assign]
    ax.status = status  # type: ignore[method-assign]


# ------------------------------------------------------------------ one drive
@pytest.mark.parametrize("url", URLS)
@pytest.mark.parametrize("how", [["--wait"], ["--confirm"], ["--wait", "--confirm"]])
def test_a_move_on_a_disabled_drive_exits_1_and_sends_nothing(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[AsyncAxis], Any]],
        url: str, how: list[str]) -> None:
    on_connect.append(disabled)
    code, out, err = run(capsys, "--url", url, "move", *how, "1rev")
    assert code == F.EXIT_FAULT, err
    assert err.count("\n") == 1 and "is disabled (motor free): the move was not sent" in err
    assert "enable the drive" in err
    assert sent == [] and out == ""


@pytest.mark.parametrize("url", URLS)
def test_a_move_on_a_drive_in_alarm_exits_1(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[AsyncAxis], Any]],
        url: str) -> None:
    on_connect.append(alarmed)
    code, _, err = run(capsys, "--url", url, "move", "--wait", "1rev")
    assert code == F.EXIT_FAULT and "(latched); the move was not sent" in err, err


@pytest.mark.parametrize("url", ["sim://dyn232?fast=1", "sim://easycan?fast=1"])
def test_a_waited_move_that_stops_off_target_exits_1(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[AsyncAxis], Any]],
        url: str) -> None:
    on_connect.append(stops_off_target)
    code, out, err = run(capsys, "--url", url, "move", "--wait", "1rev")
    assert code == F.EXIT_FAULT, err
    assert "counts from the target" in err and "outside its in-position window" in err
    assert out == ""


def test_a_waited_move_that_arrives_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "--url", "sim://easycan?fast=1", "move", "--wait", "--confirm",
                         "1rev", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert abs(doc["position"] - doc["target"]) <= doc["window"]


# ------------------------------------------------------------------ machine path
@pytest.mark.parametrize("axis", ["x", "c"])
@pytest.mark.parametrize("how", [["--wait"], ["--confirm"], ["--wait", "--confirm"]])
def test_a_machine_move_on_a_disabled_drive_exits_1(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[AsyncAxis], Any]],
        tmp_path: Path, axis: str, how: list[str]) -> None:
    on_connect.append(disabled)
    m = str(write_machine(tmp_path))
    code, out, err = run(capsys, "--machine", m, "--axis", axis, "move", "20", *how)
    assert code == F.EXIT_FAULT, err
    assert f"axis {axis} (drive 1" in err or f"axis {axis} (drive" in err
    assert "is disabled (motor free): the move was not sent" in err and out == ""
    assert sent == []


def test_a_machine_move_that_stops_off_target_exits_1(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[AsyncAxis], Any]],
        tmp_path: Path) -> None:
    on_connect.append(stops_off_target)
    m = str(write_machine(tmp_path))
    code, _, err = run(capsys, "--machine", m, "--axis", "x", "move", "20", "--wait")
    assert code == F.EXIT_FAULT and "outside its in-position window" in err, err


def test_a_machine_confirmed_move_keeps_the_soft_limits_and_arrives(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    m = str(write_machine(tmp_path))
    code, _, err = run(capsys, "--machine", m, "--axis", "x", "move", "400", "--confirm")
    assert code == F.EXIT_USAGE and "soft limits" in err
    code, _, err = run(capsys, "--machine", m, "--axis", "x", "move", "--relative", "400",
                       "--confirm")
    assert code == F.EXIT_USAGE and "soft limits" in err
    code, out, err = run(capsys, "--machine", m, "--axis", "x", "--json", "move", "20",
                         "--confirm", "--wait")
    assert code == 0, err
    assert abs(json.loads(out)["position"] - 20.0) < 0.01


@pytest.mark.parametrize("axis", [None, "c"])
def test_machine_status_of_an_axis_in_alarm_exits_1(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[AsyncAxis], Any]],
        tmp_path: Path, axis: str | None) -> None:
    m = str(write_machine(tmp_path))
    code, _, err = run(capsys, "--machine", m, "status")
    assert code == 0, err
    on_connect.append(alarmed)
    code, out, err = run(capsys, "--machine", m, *(["--axis", axis] if axis else []), "status")
    assert code == F.EXIT_FAULT, err
    assert "axis c reports alarm 20" in err and "(latched)" in err and err.count("\n") == 1
    assert "`servobus reset`" in err
    assert out  # the table (or the axis) is shown before the error


# ------------------------------------------------------------------ the checks themselves
class StillAxis:
    """Stands still, not in position, enabled: what a YZ-AIM reports when stopped short."""

    drive_id = 4
    status_calls = 0

    def wait_idle(self, timeout: float) -> AxisStatus:
        from servobus.errors import DriveTimeout

        raise DriveTimeout("not idle")

    def position(self) -> int:
        return 50

    def status(self) -> AxisStatus:
        self.status_calls += 1
        return AxisStatus(enabled=True, moving=False, in_position=False, alarm_code=0,
                          alarm_text="", alarm_latched=False, raw=0, family="yzaim")


def test_wait_arrival_ends_once_the_motor_stood_still_off_target(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(arrival, "STILL_S", 0.05)
    axis = StillAxis()
    status = wait_arrival(axis, 60, 10)  # type: ignore[arg-type]
    assert not status.moving and not status.in_position  # ended after STILL_S, not 60 s
    assert axis.status_calls >= 2  # seen still twice, STILL_S apart
    with pytest.raises(MoveFailed, match=r"stopped at 50 counts, -50 counts from the target"):
        check_arrival("drive 4", 4, status, 50, 100, 10)
    check_arrival("drive 4", 4, status, 95, 100, 10)  # inside the window: fine
