"""The shared "stop every axis first" helper: every axis stops, whatever fails beside it."""

from __future__ import annotations

import asyncio
import contextlib

from servobus.axis.connect import connect_async
from servobus.axis.halt import halt
from servobus.errors import ServobusError


async def test_every_axis_stops_even_when_one_stop_fails() -> None:
    axis = await connect_async("sim://dyn232?ids=1,2&fast=1", drive_id=1)
    other = await axis.sibling(2)
    try:
        await axis.turn(300)
        await other.turn(300)

        async def stop(a: object, timeout_s: float) -> None:
            if a is other:
                raise ServobusError("link gone")
            await asyncio.wait_for(axis.stop(), timeout_s)

        outcome = await halt({"x": axis, "y": other}, stop=stop)
        assert outcome["x"] is None
        assert isinstance(outcome["y"], ServobusError)
        status = await axis.wait_idle(timeout=10.0)
        assert not status.alarm_latched
        assert abs(await axis.speed()) <= 1.0  # whole rpm; a holding servo dithers by one
    finally:
        await axis.close()


async def test_a_cancelled_shutdown_still_stops_the_motor() -> None:
    axis = await connect_async("sim://dyn232?fast=1", drive_id=1)
    try:
        await axis.turn(300)
        stopped = asyncio.Event()

        async def slow_stop(a: object, timeout_s: float) -> None:
            await asyncio.sleep(0)  # a yield point: the cancellation below lands mid-stop
            await axis.stop()
            stopped.set()

        task = asyncio.create_task(halt({"x": axis}, stop=slow_stop))
        await asyncio.sleep(0)  # let the halt start; no event exists before it has
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        assert stopped.is_set()
        await axis.wait_idle(timeout=10.0)
        assert abs(await axis.speed()) <= 1.0  # whole rpm; a holding servo dithers by one
    finally:
        await axis.close()
