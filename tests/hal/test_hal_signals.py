"""``servobus hal``'s stop signals in-process (no LinuxCNC: a stand-in for its ``hal``
module): SIGHUP, which a component gets when the terminal LinuxCNC was started from
closes, stops every position axis and ends the component, as SIGTERM and SIGINT do."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from rig import wait_until_async

from servobus.hal.component import serve

TABLE = """\
[axes.a]
url = "sim://easycan?fast=1&timeout=0.5"
id = 1
unit = "deg"
speed = 1800.0
accel = 36000.0
hal = "position"
"""


class Component(dict[str, Any]):
    """What ``hal.component`` gives: pins by name, ``ready`` and ``exit``."""

    def __init__(self) -> None:
        super().__init__()
        self.is_ready = self.exited = False

    def newpin(self, name: str, kind: str, direction: str) -> None:
        self[name] = 0.0 if kind == "float" else False

    def ready(self) -> None:
        self.is_ready = True

    def exit(self) -> None:
        self.exited = True


def fake_hal(component: Component) -> types.ModuleType:
    hal = types.ModuleType("hal")
    hal.HAL_FLOAT, hal.HAL_BIT, hal.HAL_S32 = "float", "bit", "s32"  # type: ignore[attr-defined]
    hal.HAL_IN, hal.HAL_OUT = "in", "out"  # type: ignore[attr-defined]
    hal.component = lambda name: component  # type: ignore[attr-defined]
    return hal


@pytest.fixture
def hangups() -> Iterator[list[int]]:
    """SIGHUPs nobody else handled (the default would end the test run)."""
    caught: list[int] = []
    previous = signal.signal(signal.SIGHUP, lambda sig, frame: caught.append(sig))
    try:
        yield caught
    finally:
        signal.signal(signal.SIGHUP, previous)


async def test_sighup_stops_every_position_axis_then_ends(
        tmp_path: Path, hangups: list[int], caplog: pytest.LogCaptureFixture) -> None:
    """The axis streams (enabled, watchdog fed, position-cmd moving) when SIGHUP comes:
    serve() stops it and returns "SIGHUP" (before: no handler, the signal went to the
    default - here the stand-in handler - and the component ran on)."""
    caplog.set_level(logging.INFO, logger="servobus.hal")
    machine = tmp_path / "table.toml"
    machine.write_text(TABLE)
    pins = Component()
    task = asyncio.create_task(serve(fake_hal(pins), machine, "servobus", 1.0))

    async def feed() -> None:  # LinuxCNC's servo thread: the watchdog and a moving command
        while True:
            pins["watchdog"] = not pins["watchdog"]
            pins["a.position-cmd"] += 0.05
            await asyncio.sleep(0.002)

    feeder = asyncio.create_task(feed())
    try:
        await wait_until_async(lambda: pins.is_ready, timeout=30, what="component ready")
        pins["a.position-cmd"] = pins["a.position-fb"]
        pins["a.enable"] = True
        await wait_until_async(lambda: "axis a: enabled, streaming" in caplog.text,
                               timeout=30, what="axis a streaming")
        os.kill(os.getpid(), signal.SIGHUP)
        assert await asyncio.wait_for(asyncio.shield(task), 30) == "SIGHUP"
    finally:
        feeder.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await feeder
        if not task.done():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
    assert hangups == [] and pins.exited
    assert "every position axis stopped" in caplog.text
