"""Every in-process stop of a YZ-AIM motor leaves it ready for the next program's move
(issue 28): ``halt`` (what the GUI's and the gateway's shutdown call) and a machine's
``stop_all``, on EasyCan and Modbus. The "next program" is a fresh Axis on the same link:
it knows nothing the stopping one kept, as a new process would not.
"""

from __future__ import annotations

from typing import Any

import pytest
from rig import wait_until_async

from servobus.axis import connect_async
from servobus.axis.base import AsyncAxis
from servobus.axis.halt import halt
from servobus.families.yzaim import registers as Y
from servobus.families.yzaim.axis import YzaimAxis
from servobus.machine.machine import open_machine_async

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]  # seconds of wall-clock motion

WINDOW = Y.POSITION_TOLERANCE_COUNTS
#: The stops here must be confirmed: halt's default 2 s bounds a shutdown, not a loaded
#: host's stalls of this process (test_stop_all_... failed once in CI with the stop timed out).
STOP_DEADLINE_S = 30.0


def fresh(axis: AsyncAxis) -> YzaimAxis[Any]:
    """Another program's view of the same motor: nothing of the stopper's state."""
    assert isinstance(axis, YzaimAxis)
    return type(axis)(axis.client, axis.drive_id, owns_client=False)


async def assert_next_move_arrives(axis: AsyncAxis) -> None:
    other = fresh(axis)
    target = await other.position() + other.revs(0.5)
    await other.move_to(target, wait=True, timeout=20)
    assert abs(await other.position() - target) <= WINDOW
    assert await other.read_param("target_speed") > 0


async def start_long_move(axis: AsyncAxis) -> None:
    await axis.enable()
    await axis.move_by(axis.revs(100))

    async def cruising() -> bool:
        return abs(await axis.speed()) > 300

    await wait_until_async(cruising, timeout=20, what="the long move under way")


@pytest.mark.parametrize("url", ["sim://easycan?fast=1", "sim://modbus?fast=1"])
async def test_halt_of_a_move_and_of_a_turn_leaves_the_motor_ready(url: str) -> None:
    axis = await connect_async(url, drive_id=1)
    try:
        await start_long_move(axis)
        assert await halt({"c": axis}, timeout_s=STOP_DEADLINE_S) == {"c": None}
        await axis.wait_idle(20)
        await assert_next_move_arrives(axis)
        await axis.turn(400)
        assert await halt({"c": axis}, timeout_s=STOP_DEADLINE_S) == {"c": None}
        await axis.wait_idle(20)
        await assert_next_move_arrives(axis)
    finally:
        await axis.close()


async def test_stop_all_of_the_builtin_machine_leaves_the_yzaim_axis_ready() -> None:
    machine = await open_machine_async(None, only=["c"])
    try:
        core = machine["c"].core()
        await start_long_move(core)
        # halt's 2 s per stop bounds a shutdown; here the stop must be confirmed, however
        # long a loaded host stalls this process (one stall of 2.4 s was seen on two cores
        # beside CPU-bound processes: the stop "timed out" with no other sequence before it)
        assert (await machine.stop_all(timeout_s=STOP_DEADLINE_S))["c"] is None
        await core.wait_idle(20)
        await assert_next_move_arrives(core)
    finally:
        await machine.close(stop=False)
