"""Loads to practise on (servobus.sim.core.loads, docs/tuning.md): presets and keys, set in a
``sim://`` URL, on ``servobus sim ...`` and through the control channel's ``load`` command."""

from __future__ import annotations

from typing import Any

import pytest

from servobus.axis.connect import connect_async
from servobus.cli.main import main
from servobus.errors import InvalidValue
from servobus.protocols.dyn232 import cli as dyn232_cli
from servobus.protocols.dyncan import cli as dyncan_cli
from servobus.protocols.easycan import cli as easycan_cli
from servobus.protocols.enip import cli as enip_cli
from servobus.protocols.modbus import cli as modbus_cli
from servobus.sim.cli_options import LOAD_OPTIONS, apply_load
from servobus.sim.core.capture import SimCapture
from servobus.sim.core.loads import PRESETS, LoadSettings, load_settings, split_load_options
from servobus.sim.dmm.control import DriveControl
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.yzaim.motor import YzaimMotor


def test_a_preset_sets_inertia_resonance_and_damping_and_keys_override_it() -> None:
    belt = PRESETS["belt"]
    assert load_settings({"load": "belt"}) == LoadSettings(belt.inertia, belt.resonance,
                                                           belt.damping)
    assert load_settings({"load": "belt", "inertia": "10", "load_torque": 0.5}) == \
        LoadSettings(10.0, belt.resonance, belt.damping, 0.5)
    assert load_settings({"resonance": 40}) == LoadSettings(resonance=40.0)
    assert load_settings({}).empty


@pytest.mark.parametrize("values", [{"load": "chain"}, {"inertia": "-1"}, {"inertia": "x"},
                                    {"resonance": 601}, {"load_torque": -101}])
def test_bad_load_keys_are_refused_with_the_key(values: dict[str, object]) -> None:
    with pytest.raises(InvalidValue, match=next(iter(values))):
        load_settings(values)


def test_split_load_options_leaves_the_others() -> None:
    rest, load = split_load_options({"fast": "1", "load": "screw", "inertia": "3"})
    assert rest == {"fast": "1"}
    assert load == LoadSettings(3.0, PRESETS["screw"].resonance, PRESETS["screw"].damping)


async def test_a_sim_url_sets_the_load_of_its_drives() -> None:
    axis = await connect_async("sim://dyn232?fast=1&load=belt&inertia=10&load_torque=0.25",
                               drive_id=1)
    try:
        source = axis.capture_source
        assert isinstance(source, SimCapture)
        drive = source.traced[0].drive
        assert isinstance(drive, VirtualDrive)
        mech = drive.mechanics()
        assert (mech["inertia"], mech["resonance"], mech["load_torque"]) == pytest.approx(
            (10.0, PRESETS["belt"].resonance, 0.25))
    finally:
        await axis.close()


async def test_a_sim_url_refuses_a_bad_load() -> None:
    with pytest.raises(InvalidValue, match="load="):
        await connect_async("sim://dyn232?fast=1&load=chain", drive_id=1)


def test_the_control_channels_load_command_takes_the_same_keys() -> None:
    drive = VirtualDrive(1)
    control = DriveControl([drive])
    reply = control.execute({"cmd": "load", "load": "screw", "resonance": 200})
    assert reply["ok"] and reply["mechanics"]["resonance"] == 200.0
    assert reply["mechanics"]["inertia"] == PRESETS["screw"].inertia
    reply = control.execute({"cmd": "load", "load_torque": -0.5, "torque_nm": 0.1})
    assert reply["mechanics"]["load_torque"] == -0.5 and reply["world"]["load_torque_nm"] == 0.1
    assert reply["mechanics"]["resonance"] == 200.0  # left as it was
    refused = control.execute({"cmd": "load", "load": "chain"})
    assert not refused["ok"] and refused["kind"] == "bad_argument"
    refused = control.execute({"cmd": "load", "inertia": 1001})
    assert not refused["ok"] and refused["kind"] == "bad_argument"


def test_apply_load_reaches_dmm_drives_and_yzaim_motors() -> None:
    drive, motor = VirtualDrive(1), YzaimMotor()
    apply_load([drive, motor], load="direct", inertia=None, resonance=None, load_torque=0.2)
    for shaft in (drive, motor.drive):
        assert shaft.mechanics()["inertia"] == PRESETS["direct"].inertia
        assert shaft.mechanics()["load_torque"] == 0.2


@pytest.mark.parametrize("module", [dyn232_cli, dyncan_cli, easycan_cli, enip_cli, modbus_cli])
def test_every_sim_command_has_the_load_flags(module: Any) -> None:
    flags = {o.flag for o in module.COMMANDS[0].options}
    assert {o.flag for o in LOAD_OPTIONS} <= flags


def test_servobus_sim_load_flags_reach_the_drives(monkeypatch: pytest.MonkeyPatch) -> None:
    made: list[VirtualDrive] = []
    real = dyn232_cli.make_drives

    def spy(*args: Any, **kwargs: Any) -> list[VirtualDrive]:
        made.extend(real(*args, **kwargs))
        return made

    monkeypatch.setattr(dyn232_cli, "make_drives", spy)
    with pytest.raises(SystemExit) as done:
        main(["sim", "dyn232", "--fast", "--duration", "0.05", "--load", "belt",
              "--inertia", "8", "--resonance", "45"])
    assert done.value.code in (0, None)
    assert made and made[0].mechanics()["inertia"] == 8.0
    assert made[0].mechanics()["resonance"] == 45.0


def test_servobus_sim_refuses_a_bad_load_flag() -> None:
    with pytest.raises(SystemExit) as done:
        main(["sim", "dyn232", "--fast", "--duration", "0.05", "--inertia", "-1"])
    assert done.value.code == 2
