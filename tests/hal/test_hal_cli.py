"""``servobus hal``'s one-line refusals, before LinuxCNC is touched."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from machine.machine_rig import Run, write_machine
from machine.machine_rig import run as run  # the fixture, for this module

from servobus.hal.module import PATH_ENV

CELL = '[axes.c]\nurl = "sim://easycan?fast=1"\nunit = "deg"\n'


def test_without_a_machine_file_it_says_what_it_needs(run: Run) -> None:
    code, _, err = run("hal")
    assert code == 2 and "servobus hal needs --machine FILE" in err


def test_a_machine_file_mistake_is_one_line(run: Run, tmp_path: Path) -> None:
    path = write_machine(tmp_path, CELL + 'hal = "torque"\n')
    code, _, err = run("hal", "--machine", str(path))
    assert code == 2 and "axis c: hal: must be one of monitor, position" in err


def test_without_linuxcnc_s_hal_module_it_says_how_to_get_it(
        run: Run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    empty = tmp_path / "no-hal-here"
    empty.mkdir()
    monkeypatch.setenv(PATH_ENV, str(empty))
    monkeypatch.delitem(sys.modules, "hal", raising=False)
    code, _, err = run("hal", "--machine", str(write_machine(tmp_path, CELL)))
    assert code == 2
    assert "hal module cannot be imported" in err and "linuxcnc-uspace" in err
