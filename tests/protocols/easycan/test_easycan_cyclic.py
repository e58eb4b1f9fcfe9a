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
        assert abs(await axis.position() - start) <= 2
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
        assert abs(await axis.position() - (start + 1000)) <= 2
    finally:
        await axis.close()


async def _at(axis: AsyncAxis, counts: int) -> bool:
    return abs(await axis.position() - counts) <= 2
