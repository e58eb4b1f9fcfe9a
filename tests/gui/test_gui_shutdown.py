"""The GUI's shutdown stops every axis first, whatever else fails (issue 17.1).

In-process on the app's lifespan: an axis turning at 300 rpm and a scope sampler whose task
died with an exception; after the shutdown the drive, run on for a simulated second, is at
standstill, and the connection is closed.
"""

from __future__ import annotations

import asyncio

import pytest
from rig import wait_until_async

from servobus.gui.app import create_app
from servobus.gui.state import GuiState
from servobus.sim.dmm.drive import VirtualDrive

pytestmark = pytest.mark.timeout(60)


def drive_of(gui: GuiState, axis_id: int) -> VirtualDrive:
    source = gui.fleet.get(axis_id).axis.capture_source
    drive: VirtualDrive = next(d for d in source.drives  # type: ignore[union-attr]
                               if d.drive_id == axis_id)
    return drive


async def sampler_bug() -> None:
    raise RuntimeError("a bug in the sampler")


async def turning_axis_and_dead_sampler(gui: GuiState) -> VirtualDrive:
    axis = gui.fleet.get(1).axis
    await axis.turn(300)
    drive = drive_of(gui, 1)
    await wait_until_async(lambda: _at(drive, 300), timeout=10, what="axis 1 at 300 rpm")
    sampler = gui.samplers[2]
    sampler._run = sampler_bug  # type: ignore[method-assign]
    sampler.subscribe(["position"])
    task = sampler._task
    assert task is not None
    await asyncio.wait([task])
    assert isinstance(task.exception(), RuntimeError)
    return drive


async def _at(drive: VirtualDrive, rpm: float) -> bool:
    return abs(drive.speed_rpm - rpm) < 5


def run_on(drive: VirtualDrive, seconds: float) -> float:
    """The drive's speed after ``seconds`` more of simulated time (its clock has stopped)."""
    drive.advance_to(drive.time + seconds)
    return drive.speed_rpm


async def test_a_dead_sampler_does_not_keep_an_axis_turning_after_shutdown() -> None:
    app = create_app()
    async with app.router.lifespan_context(app):
        gui: GuiState = app.state.gui
        drive = await turning_axis_and_dead_sampler(gui)
    assert gui.halted == {1: None, 2: None, 3: None}
    assert abs(run_on(drive, 1.0)) < 0.5  # at standstill (was 300 rpm)
    assert gui.fleet.get(1).stats.as_dict()["calls"] >= 1  # the stop went through the counter


async def test_a_cancelled_shutdown_still_stops_every_axis() -> None:
    app = create_app()
    gui: GuiState | None = None
    lifespan = app.router.lifespan_context(app)
    await lifespan.__aenter__()
    gui = app.state.gui
    drive = await turning_axis_and_dead_sampler(gui)
    shutdown = asyncio.create_task(lifespan.__aexit__(None, None, None))
    await asyncio.sleep(0)  # the shutdown has started its stop
    shutdown.cancel()
    with pytest.raises(asyncio.CancelledError):
        await shutdown
    assert gui.halted is None or gui.halted[1] is None
    assert abs(run_on(drive, 1.0)) < 0.5  # at standstill (was 300 rpm)
