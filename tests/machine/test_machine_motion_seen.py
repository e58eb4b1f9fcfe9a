"""A drive restarted while it moved is flagged, whatever the moment of the restart (issue 29,
docs/machine.md "Motion seen to end"): a DMM drive keeps no mark of a power cycle, so a drive
that restarts near where it started looks as if it never moved, and only the machine's
"a motion runs" can tell. A front end's poll under way while a motion command goes out, or
a stop, must not decide that; a poll that sees the drive moving, whoever moved it, does.
Each test drops the link by hand (as the machine does) and puts a drive that powered up at
0 behind the axis (what a reopen finds after a restart)."""

from __future__ import annotations

import asyncio
from pathlib import Path

from machine_rig import write_machine
from rig import wait_until_async

from servobus.axis import connect_async
from servobus.errors import MachineLinkError
from servobus.machine import open_machine_async
from servobus.machine.axis import AsyncMachineAxis

#: Paced like the wire: a reply comes a packet time after its request, so a read can be
#: answered before a command queued behind it reaches the drive.
ONE_AXIS = '[axes.a]\nurl = "sim://dyn232"\nid = 1\nunit = "rev"\n'


async def restart_behind(axis: AsyncMachineAxis) -> None:
    """The link drops and comes back to a drive that powered up at 0; the power check.
    The axis gets its own drive back after (the test stops it, the machine closes it)."""
    own = axis.axis
    axis.went_offline(MachineLinkError("the link dropped"))
    restarted = await connect_async("sim://dyn232?fast=1", drive_id=1)
    axis.axis = restarted
    try:
        await axis.check_power()
    finally:
        axis.axis = own
        await restarted.close()


async def test_a_poll_answered_while_the_first_move_reads_its_gear_does_not_end_it(
        tmp_path: Path) -> None:
    """The first move of a DMM axis reads GEAR_NUM before it sends: a status read begun
    after the move was counted goes out before the move itself and answers "not moving".
    The drive restarts just after the move went out, near 0: flagged (the GUI's recovery
    test missed the power loss that way in a CI run)."""
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS))
    try:
        axis = machine["a"]
        core = axis.core()
        move = asyncio.create_task(axis.move_to(20.0))
        await asyncio.sleep(0)  # the move is under way: its GEAR_NUM read went out
        poll = asyncio.create_task(axis.status())  # the GUI's poll, queued behind that read
        await move
        assert not (await poll).moving  # answered before the drive got the move
        assert (await core.status()).moving  # ... which it runs now
        await restart_behind(axis)
        assert axis.interrupted == "a commanded motion may not have finished"
        assert axis.power_lost and "unverified" in str(axis.power_lost_reason)
        await core.stop()
    finally:
        await machine.close()


async def test_a_motion_from_outside_the_machine_seen_running_is_interrupted(
        tmp_path: Path) -> None:
    """A motion the machine did not command (the GUI's waves and steps go to the Axis) that
    a poll saw running: a restart meanwhile is flagged, though no position was read."""
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS))
    try:
        axis = machine["a"]
        core = axis.core()
        await core.move_by(50 * core.counts_per_rev)
        await wait_until_async(lambda: _moving(axis), timeout=30, what="the drive moving")
        await restart_behind(axis)
        assert axis.interrupted == "the drive was seen moving and not yet seen to stop"
        assert axis.power_lost
        await core.stop()
    finally:
        await machine.close()


async def test_a_poll_under_way_when_the_axis_stops_does_not_restart_the_motion(
        tmp_path: Path) -> None:
    """The other way round: a poll sent before a stop that answers "moving" after it says
    nothing of the stopped axis; a later drop interrupts nothing."""
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS))
    try:
        axis = machine["a"]
        await axis.move_by(50.0)
        await wait_until_async(lambda: _moving(axis), timeout=30, what="the axis moving")
        poll = asyncio.create_task(axis.status())
        await asyncio.sleep(0)  # the poll goes out first
        await axis.stop()
        assert (await poll).moving  # answered before the drive got the stop
        axis.went_offline(MachineLinkError("the link dropped"))
        assert axis.interrupted is None
    finally:
        await machine.close()


async def _moving(axis: AsyncMachineAxis) -> bool:
    return (await axis.status()).moving
