"""The event loop for the loops servobus owns: uvloop when installed, asyncio's otherwise.

Decision (issue 22): ``pip install servobus[fast]`` adds uvloop (Linux, macOS). servobus
then uses it for the loops it creates itself - the sync Axis facade's loop thread, where it
has one (so the ``servobus`` CLI too), the GUI server, ``servobus enip discover`` - and never
for a loop a user runs: ``connect_async`` and every async client work on whatever loop they
are awaited on. The paced simulators keep
:func:`servobus.sim.fine_selector.fine_event_loop`: libuv's timers have millisecond
resolution, and a paced line needs microseconds. Measured on the
benchmarks (docs/performance.md): uvloop cuts the CPU time of an explicit EtherNet/IP or
a DYN232M round trip by about a third, and the loop's share of it by more.

``SERVOBUS_LOOP=asyncio`` in the environment turns it off (e.g. to compare, or when a
debugger wants the pure-Python loop).
"""

from __future__ import annotations

import asyncio
import os
import sys
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

T = TypeVar("T")

#: Environment variable: ``asyncio`` keeps asyncio's own loop even with uvloop installed.
ENV = "SERVOBUS_LOOP"


def _uvloop_factory() -> Callable[[], asyncio.AbstractEventLoop] | None:
    if os.environ.get(ENV, "").strip().lower() == "asyncio" or sys.platform == "win32":
        return None
    try:
        import uvloop
    except ImportError:
        return None
    factory: Callable[[], asyncio.AbstractEventLoop] = uvloop.new_event_loop
    return factory


def fast_available() -> bool:
    """uvloop is installed and not turned off: :func:`new_event_loop` returns one."""
    return _uvloop_factory() is not None


def new_event_loop() -> asyncio.AbstractEventLoop:
    """A new loop for servobus's own use: uvloop's when available, else asyncio's."""
    factory = _uvloop_factory()
    return factory() if factory is not None else asyncio.new_event_loop()


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run(main)`` on :func:`new_event_loop` (for servobus's own entry points)."""
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        return runner.run(main)


def loop_name(loop: asyncio.AbstractEventLoop) -> str:
    """``uvloop`` or ``asyncio`` (for benchmark and log lines)."""
    return "uvloop" if type(loop).__module__.startswith("uvloop") else "asyncio"
