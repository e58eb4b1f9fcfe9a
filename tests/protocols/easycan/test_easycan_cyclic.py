"""Cyclic synchronous position on EasyCan (stream_cycles: the 2 ms cache with the sync
signal, one motor): the motor takes every cycle's position, rests at the last one, and
takes ordinary moves again afterwards, whatever ended the stream."""

from __future__ import annotations

import pytest
from rig import wait_until_async

from servobus.axis.base import AsyncAxis
from servobus.axis.capabilities import Capability
from servobus.axis.connect import connect_async
from servobus.errors import ArgumentRangeError
from servobus.protocols.easycan.messages import WriteRequest
from servobus.transport.base import Direction

SYNC_CONTROL = 0x1C  # YZ-AIM manual 5.2: a write of 1 is the synchronisation signal


async def test_the_motor_follows_each_cycle_and_rests_at_the_last() -> None:
    axis = await connect_async("sim://easycan?fast=1", drive_id=1)
    try:
        assert axis.supports(Capability.CYCLIC_POSITION)
        await axis.enable()
        start = await axis.position()
        steps = iter(range(1, 201))

        def next_position() -> int | None:
            step = next(steps, None)
            return None if step is None else start + 40 * step  # 40 counts per 2 ms

        stats = await axis.stream_cycles(next_position)
        assert stats.cycles + stats.skipped == 200
        await wait_until_async(lambda: _at(axis, start + 8000), timeout=10,
                               what="at the last position")
        await axis.move_to(start, wait=True, timeout=10)  # sync is off again: moves work
        # in position is a window (POSITION_TOLERANCE_COUNTS): the last counts settle after it
        await wait_until_async(lambda: _at(axis, start), timeout=10, what="back at the start")
    finally:
        await axis.close()


async def test_a_position_out_of_range_ends_the_stream_before_it_is_sent() -> None:
    axis = await connect_async("sim://easycan?fast=1", drive_id=1)
    try:
        await axis.enable()
        start = await axis.position()
        with pytest.raises(ArgumentRangeError):
            await axis.stream_cycles(lambda: 2**40)
        assert abs(await axis.position() - start) <= 2
        await axis.move_to(start + 1000, wait=True, timeout=10)
        await wait_until_async(lambda: _at(axis, start + 1000), timeout=10,
                               what="at the target (the in-position window, then settled)")
    finally:
        await axis.close()


async def _at(axis: AsyncAxis, counts: int) -> bool:
    return abs(await axis.position() - counts) <= 2


async def test_two_motors_of_one_bus_stream_together_on_one_signal() -> None:
    first = await connect_async("sim://easycan?ids=1,2&fast=1", drive_id=1)
    second = await first.sibling(2)
    sent: list[object] = []
    await first.add_trace(lambda direction, item, t: sent.append(item)
                          if direction is Direction.TX else None)
    try:
        assert first.supports(Capability.CYCLIC_GROUP)
        assert first.sync_group() is second.sync_group() is not None
        for axis in (first, second):
            await axis.enable()
        starts = [await first.position(), await second.position()]
        steps = iter(range(1, 101))
        step = 0

        def lead() -> int | None:  # asked first every cycle: it ends the stream for both
            nonlocal step
            step = next(steps, 0)
            return None if not step else starts[0] + 40 * step

        stats = await first.stream_cycles_together(
            [(first, lead), (second, lambda: starts[1] - 40 * step)])
        assert stats.cycles + stats.skipped == 100 and stats.frames == 2 * stats.cycles
        signals = [i for i, item in enumerate(sent) if isinstance(item, WriteRequest)
                   and item.address == SYNC_CONTROL and item.values == (1,)]
        assert sorted(sent[i].slave for i in signals) == [1, 2]  # type: ignore[attr-defined]
        assert signals[1] == signals[0] + 1  # one signal: back to back (either first), once
        await wait_until_async(lambda: _at(first, starts[0] + 4000), timeout=10,
                               what="motor 1 at its last position")
        await wait_until_async(lambda: _at(second, starts[1] - 4000), timeout=10,
                               what="motor 2 at its last position")
    finally:
        await second.close()
        await first.close()


async def test_a_motor_of_another_bus_is_refused_before_anything_is_sent() -> None:
    first = await connect_async("sim://easycan?fast=1", drive_id=1)
    other = await connect_async("sim://easycan?fast=1", drive_id=2)
    try:
        with pytest.raises(ArgumentRangeError, match="does not stream together"):
            await first.stream_cycles_together([(first, lambda: 0), (other, lambda: 0)])
    finally:
        await other.close()
        await first.close()
