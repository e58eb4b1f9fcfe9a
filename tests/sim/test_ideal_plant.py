"""The ideal plant (``servobus sim ... --plant ideal``, servobus.sim.core.engine): the shaft
follows the reference exactly, and a drive cruising at a constant speed advances in O(1)."""

from __future__ import annotations

from typing import Any

import pytest
from rig import wait_until_async

from servobus.axis.connect import connect_async
from servobus.cli.main import main
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.protocols.dyn232 import cli as dyn232_cli
from servobus.sim.cli_options import apply_load
from servobus.sim.core import constants as K
from servobus.sim.core.capture import SimCapture
from servobus.sim.core.motor import Motor
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.yzaim.motor import YzaimMotor


def turning_motor(ideal: bool, rpm: float = 120.0) -> Motor:
    motor = Motor(U.MODELS[U.DEFAULT_MODEL])
    motor.set_ideal(ideal)
    motor.set_profile(600.0, 3000.0)
    motor.enable()
    motor.run_speed(rpm)
    return motor


def run_in_ticks(motor: Motor, until: float, tick: float = 0.004) -> None:
    """As a server's clock does: many short advances."""
    t = motor.time
    while t < until:
        t = min(until, t + tick)
        motor.advance_to(t)


def test_the_ideal_shaft_is_the_reference_with_no_current() -> None:
    motor = turning_motor(True)
    run_in_ticks(motor, 0.02)  # still ramping (3000 rpm/s to 120 rpm takes 40 ms)
    assert 0.0 < motor.speed_rpm < 120.0
    assert motor.position_error == 0.0 and motor.current_a == 0.0
    run_in_ticks(motor, 1.0)
    assert motor.speed_rpm == pytest.approx(120.0)
    assert motor.position_error == 0.0 and motor.current_a == 0.0


def test_ideal_and_physics_drives_follow_the_same_reference() -> None:
    ideal, physics = turning_motor(True), turning_motor(False)
    for motor in (ideal, physics):
        run_in_ticks(motor, 1.5)
    # the physical shaft lags its reference by the following error; the ideal one does not
    physical_reference = physics.shaft_position + physics.position_error
    assert ideal.shaft_position == pytest.approx(physical_reference, abs=1e-3)


def test_a_cruising_ideal_drive_advances_in_one_step_as_in_many(
        monkeypatch: pytest.MonkeyPatch) -> None:
    stepped, jumped = turning_motor(True), turning_motor(True)
    for motor in (stepped, jumped):
        run_in_ticks(motor, 0.5)  # past the ramp: cruising

    def no_loop(n: int) -> int:
        raise AssertionError("a cruising ideal drive ran its control periods one by one")

    for motor in (stepped, jumped):
        monkeypatch.setattr(motor._engine, "_run_position", no_loop)
    run_in_ticks(stepped, 20.5)
    jumped.advance_to(20.5)
    assert jumped.periods == stepped.periods == round(20.5 * K.CONTROL_HZ)
    assert jumped.shaft_position == pytest.approx(stepped.shaft_position, rel=1e-9)
    assert jumped.speed_rpm == pytest.approx(120.0)
    # 20 s at 120 rpm: 40 revolutions beyond where it was at 0.5 s
    turned = (jumped.shaft_position - turning_motor_at(0.5)) / U.COUNTS_PER_REV
    assert turned == pytest.approx(40.0, rel=1e-6)


def turning_motor_at(t: float) -> float:
    motor = turning_motor(True)
    run_in_ticks(motor, t)
    return motor.shaft_position


def test_an_ideal_move_lands_exactly_and_the_drive_settles() -> None:
    motor = Motor(U.MODELS[U.DEFAULT_MODEL])
    motor.set_ideal(True)
    motor.set_profile(600.0, 3000.0)
    motor.enable()
    assert motor.move_to_counts(3 * U.COUNTS_PER_REV)
    run_in_ticks(motor, 2.0)
    assert motor.shaft_position == 3 * U.COUNTS_PER_REV
    assert motor.speed_rpm == 0.0 and motor.position_error == 0.0
    assert motor._engine.settled


def test_apply_load_sets_the_ideal_plant_on_dmm_drives_and_yzaim_motors() -> None:
    drive, motor = VirtualDrive(1), YzaimMotor()
    apply_load([drive, motor], load=None, inertia=None, resonance=None, load_torque=None,
               plant="ideal")
    assert drive._engine.ideal and motor.drive._engine.ideal
    other = VirtualDrive(2)
    apply_load([other], load=None, inertia=None, resonance=None, load_torque=None)
    assert not other._engine.ideal


def test_the_ideal_plant_refuses_a_load() -> None:
    with pytest.raises(ArgumentRangeError, match="no mechanics"):
        apply_load([], load="belt", inertia=None, resonance=None, load_torque=None,
                   plant="ideal")
    with pytest.raises(SystemExit) as done:
        main(["sim", "dyn232", "--fast", "--duration", "0.05", "--plant", "ideal",
              "--inertia", "5"])
    assert done.value.code == 2


def test_servobus_sim_plant_ideal_reaches_the_drives(monkeypatch: pytest.MonkeyPatch) -> None:
    made: list[VirtualDrive] = []
    real = dyn232_cli.make_drives

    def spy(*args: Any, **kwargs: Any) -> list[VirtualDrive]:
        made.extend(real(*args, **kwargs))
        return made

    monkeypatch.setattr(dyn232_cli, "make_drives", spy)
    with pytest.raises(SystemExit) as done:
        main(["sim", "dyn232", "--fast", "--duration", "0.05", "--ids", "1,2",
              "--plant", "ideal"])
    assert done.value.code in (0, None)
    assert len(made) == 2 and all(d._engine.ideal for d in made)


async def test_a_sim_url_turns_an_ideal_drive_and_refuses_a_load_with_it() -> None:
    axis = await connect_async("sim://dyn232?fast=1&plant=ideal", drive_id=1)
    try:
        source = axis.capture_source
        assert isinstance(source, SimCapture)
        drive = source.traced[0].drive
        assert isinstance(drive, VirtualDrive) and drive._engine.ideal
        await axis.enable()
        await axis.turn(60)
        await wait_until_async(lambda: drive.speed_rpm == pytest.approx(60.0), timeout=30.0)
        assert drive.current_a == 0.0 and drive.position_error == 0.0
        await axis.stop()
    finally:
        await axis.close()
    for url in ("sim://dyn232?fast=1&plant=ideal&load=belt", "sim://dyn232?plant=kinematic"):
        with pytest.raises(ArgumentRangeError, match="plant="):
            await connect_async(url, drive_id=1)
