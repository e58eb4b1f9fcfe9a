"""A machine axis while it is tuned (MachineAxis.tune): other motion is refused, Stop cancels
the run (the tuner's abort: the kept gains back), and revert_gains writes only what differs.
Wall clock on a virtual DYN232M drive; the run is stopped after its first test move."""

from __future__ import annotations

import asyncio

import pytest

from servobus.errors import OwnerError, ServobusError
from servobus.machine import open_url_machine_async
from servobus.tune.tuner import Trial

URL = "sim://dyn232?fast=1&load=direct&inertia=10"


async def test_a_tuned_axis_refuses_other_motion_and_stop_cancels_the_run() -> None:
    async with await open_url_machine_async(URL) as machine:
        axis = machine["axis"]
        gains = ("main_gain", "speed_gain", "int_gain", "trq_cons")
        kept = {n: await axis.core().read_param(n) for n in gains}
        moved = asyncio.Event()

        def seen(trial: Trial) -> None:
            moved.set()

        run = asyncio.create_task(axis.tune(8192, owner="page 1", on_trial=seen))
        await asyncio.wait_for(moved.wait(), 60)
        assert axis.tuning_owner == "page 1"
        with pytest.raises(OwnerError, match="being tuned by page 1"):
            await axis.move_to(0)
        with pytest.raises(OwnerError, match="being tuned by page 1"):
            await axis.jog(100.0, owner="page 2")
        with pytest.raises(OwnerError, match="one run at a time"):
            await axis.tune(8192, owner="page 1")
        await axis.stop()  # Stop always wins: the run is cancelled and aborts
        with pytest.raises(asyncio.CancelledError):
            await asyncio.wait_for(run, 60)
        assert axis.tuning_owner is None
        assert {n: await axis.core().read_param(n) for n in gains} == kept
        # revert_gains: only the gains that differ are written
        await axis.core().write_param("speed_gain", kept["speed_gain"] + 10)
        assert await axis.revert_gains(kept) == {"speed_gain": kept["speed_gain"]}
        assert await axis.revert_gains(kept) == {}
        # the goal reaches the tuner: an unknown one is refused before anything moves
        with pytest.raises(ServobusError, match="goal 'fast'"):
            await axis.tune(8192, goal="fast")
        assert axis.tuning_owner is None
