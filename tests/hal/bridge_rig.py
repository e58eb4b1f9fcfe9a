"""The in-process bridge tests' rig (no LinuxCNC): pins as a dict, the bridge's task."""

from __future__ import annotations

import asyncio

import pytest
from rig import wait_until_async

from servobus.hal.bridge import AxisBridge
from servobus.hal.pins import AXIS_PINS, COMPONENT_PINS, Pins, axis_pin


def blank_pins(axes: list[str]) -> Pins:
    pins: Pins = {p.name: (0.0 if p.kind == "float" else False) for p in COMPONENT_PINS}
    for axis in axes:
        for p in AXIS_PINS:
            pins[axis_pin(axis, p.name)] = {"float": 0.0, "bit": False, "s32": 0}[p.kind]
    return pins



async def stopped(task: asyncio.Task[None]) -> None:
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


async def cycles(bridge: AxisBridge, count: int) -> None:
    """Until the axis's loop has run ``count`` more cycles (what it would do, it did)."""
    until = bridge.cycles + count
    await wait_until_async(lambda: bridge.cycles >= until, what=f"{count} cycles")


