"""A drive in alarm, in-process: ``status`` exits 1 and shows the alarm the same way on every
protocol; ``servobus reset`` clears a latched alarm; the advice names ``servobus reset``.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from cli_rig import run

from servobus import axis as axis_package
from servobus.axis import Axis
from servobus.axis.types import AxisStatus
from servobus.cli import failures as F
from servobus.sim.dmm.control import DriveControl

URLS = ["sim://dyn232?fast=1", "sim://dyncan?fast=1", "sim://easycan?fast=1", "sim://enip",
        "sim://modbus?fast=1"]
#: A latched alarm every family has: (family name, code).
LATCHED = {"dmm-dyn2": 2, "dmm-dyn5": 2, "yzaim": 0x14}



@pytest.fixture
def on_connect(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Callable[[Axis], None]]]:
    """Actions run on each Axis the CLI opens, right after it is connected."""
    actions: list[Callable[[Axis], None]] = []
    real = axis_package.connect

    def connect(url: str, **options: Any) -> Axis:
        ax = real(url, **options)
        for action in actions:
            action(ax)
        return ax

    monkeypatch.setattr(axis_package, "connect", connect)
    yield actions


def alarmed(ax: Axis) -> None:
    """The drive's status as it decodes, with the family's latched alarm in it."""
    core = ax.core
    real = core.status
    code = LATCHED[ax.family.name]

    async def status() -> AxisStatus:
        st = await real()
        return dataclasses.replace(st, alarm_code=code, alarm_text=ax.family.alarm_text(code),
                                   alarm_latched=True, enabled=False)

    core.status = status  # type: ignore[method-assign]


@pytest.mark.parametrize("url", URLS)
def test_status_in_alarm_exits_1_the_same_way_on_every_protocol(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[Axis], None]],
        url: str) -> None:
    on_connect.append(alarmed)
    code, out, err = run(capsys, "--url", url, "status")
    assert code == F.EXIT_FAULT
    alarm_row = next(line for line in out.splitlines() if line.split()[:1] == ["alarm"])
    assert alarm_row.split(None, 1)[1].endswith("(latched)")
    assert "None" not in out
    assert err.count("\n") == 1 and err.startswith("error: drive ")
    assert "`servobus reset`" in err and "Axis.reset()" not in err

    code, out, err = run(capsys, "--url", url, "status", "--json")
    assert code == F.EXIT_FAULT
    doc = json.loads(out)
    family = doc["family"]
    assert (doc["alarm_code"], doc["alarm_latched"]) == (LATCHED[family], True)
    assert doc["alarm"] and doc["enabled"] is False
    assert "`servobus reset`" in err


@pytest.mark.parametrize("url", URLS)
def test_status_without_alarm_exits_0(capsys: pytest.CaptureFixture[str], url: str) -> None:
    code, out, err = run(capsys, "--url", url, "status")
    assert code == 0, err
    assert any(line.split() == ["alarm", "none"] for line in out.splitlines()), out


def trip_over_current(ax: Axis) -> None:
    """A real latched alarm in the DMM virtual drive (alarm 2, over current)."""
    DriveControl(ax.core.capture_source.drives).fault(None, "over_current")


@pytest.mark.parametrize("url", ["sim://dyn232?fast=1", "sim://dyn232", "sim://dyncan?fast=1",
                                 "sim://enip"])
def test_reset_clears_a_latched_alarm(capsys: pytest.CaptureFixture[str],
                                      on_connect: list[Callable[[Axis], None]],
                                      url: str) -> None:
    on_connect.append(trip_over_current)
    code, out, err = run(capsys, "--url", url, "status", "--json")
    assert code == F.EXIT_FAULT and json.loads(out)["alarm_code"] == 2, err
    code, out, err = run(capsys, "--url", url, "reset", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["alarm_before"] == 2 and doc["alarm_code"] == 0 and doc["alarm"] == ""
    code, out, err = run(capsys, "--url", url, "reset")
    assert code == 0, err
    assert "alarm before: 2 over current (latched)" in out


@pytest.mark.parametrize("url", ["sim://easycan?fast=1", "sim://modbus?fast=1"])
def test_reset_on_yzaim_is_output_enable_off_then_on(capsys: pytest.CaptureFixture[str],
                                                      url: str) -> None:
    code, out, err = run(capsys, "--url", url, "reset", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["alarm_before"] == 0 and doc["enabled"] is True


def test_the_alarm_advice_names_the_reset_command() -> None:
    from servobus.errors import DriveAlarm

    code, line = F.describe(DriveAlarm("drive 1 alarm 2: over current"))
    assert code == F.EXIT_FAULT and "`servobus reset`" in line and "Axis.reset()" not in line


def test_a_notice_exits_1_without_asking_for_a_reset(
        capsys: pytest.CaptureFixture[str], on_connect: list[Callable[[Axis], None]]) -> None:
    def battery_warning(ax: Axis) -> None:  # YZ-AIM 0x13: the motor keeps working
        core = ax.core
        real = core.status

        async def status() -> AxisStatus:
            return dataclasses.replace(await real(), alarm_code=0x13,
                                       alarm_text=ax.family.alarm_text(0x13))

        core.status = status  # type: ignore[method-assign]

    on_connect.append(battery_warning)
    code, out, err = run(capsys, "--url", "sim://modbus?fast=1", "status")
    assert code == F.EXIT_FAULT
    assert "(notice, not latched)" in out and "a notice, not latched" in err
    assert "servobus reset" not in err
