"""The machine file's ``hal`` key (docs/machine.md)."""

from __future__ import annotations

import pytest

from servobus.errors import MachineFileError
from servobus.machine.config import parse_machine

AXIS = '[axes.c]\nurl = "sim://easycan?fast=1"\nunit = "deg"\n'


def test_hal_defaults_to_monitor() -> None:
    assert parse_machine(AXIS).axes[0].hal == "monitor"


def test_a_position_axis_names_its_speed_and_accel() -> None:
    spec = parse_machine(AXIS + 'hal = "position"\nspeed = 90\naccel = 900\n')
    assert spec.axes[0].hal == "position"
    with pytest.raises(MachineFileError, match="axis c: hal: a position axis needs speed"):
        parse_machine(AXIS + 'hal = "position"\nspeed = 90\n')


def test_an_unknown_mode_is_one_line() -> None:
    with pytest.raises(MachineFileError, match="axis c: hal: must be one of monitor, position"):
        parse_machine(AXIS + 'hal = "torque"\n')
