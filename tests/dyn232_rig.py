"""Test rig (not a test module): a DYN232M client and a virtual line on the in-process pair.

``push=True`` gives the client a push-capable cable (its receive callback path, as over TCP
and ``sim://``); ``push=False`` a pull-only one (its ``read()`` loop, as over pyserial).
The drives run in stepped virtual time: each chunk the line receives advances them by
``STEP_S``, so nothing waits on the wall clock except the deadline tests themselves.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest

from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.protocols.dyn232.device import Dyn232Line
from servobus.sim.dmm.drive import VirtualDrive
from servobus.transport.base import Direction
from servobus.transport.pair import Manipulator, PairStream, open_pair
from servobus.transport.trace import ByteCounter, TraceRecorder

STEP_S = 0.02
MARGIN_S = 0.04  # deadline checks: < the 50 ms lateness they must catch
EARLY_S = 0.001  # timer granularity: a deadline may not fire earlier than this
# A deadline check passes once one run fits the margin; a loaded machine makes single runs
# late at random, a lateness bug makes every run late. Idle, the first run fits; under load
# more runs give the machine more chances (the late side is a benchmark figure, the check is
# that on-time is possible), so the count is generous and costs nothing when idle.
REPEATS = 12
PATHS = {"push": True, "pull": False}  # pytest ids -> open_pair(push=...)


class Rig:
    """Host client + virtual line on one cable, with the manipulator and byte counters."""

    def __init__(self, ids: tuple[int, ...], *, push: bool, **client_kw: Any) -> None:
        self.faults = Manipulator()
        self.host, self.device = open_pair(self.faults, push=push)
        self.drives = [VirtualDrive(i) for i in ids]
        self.line = Dyn232Line(self.drives)
        self.wire = ByteCounter()  # bytes as written by each end, before faults
        self.host.add_trace(self._count(Direction.TX))
        self.device.add_trace(self._count(Direction.RX))
        self.client = AsyncDyn232Client(self.host, **client_kw)
        self.trace = TraceRecorder()
        self.client.add_trace(self.trace)

    def _count(self, wanted: Direction) -> Callable[[Direction, bytes, float], None]:
        def hook(d: Direction, data: bytes, t: float) -> None:
            if d is wanted:
                self.wire(d, data, t)

        return hook

    @property
    def uses_push(self) -> bool:
        """Whether the client installed a receiver (push path) rather than reading."""
        return self.host._receiver is not None

    def axis(self, drive_id: int) -> Dyn232Axis:
        return Dyn232Axis(self.client, drive_id, owns_client=False)

    async def serve(self, device: PairStream) -> None:
        try:
            while True:
                data = await device.read()
                for drive in self.drives:
                    drive.advance(STEP_S)
                reply = self.line.receive(data)
                if reply:
                    await device.write(reply)
        except ConnectionError:
            pass


@asynccontextmanager
async def rig(ids: tuple[int, ...] = (0,), *, push: bool = True,
              **client_kw: Any) -> AsyncIterator[Rig]:
    r = Rig(ids, push=push, **client_kw)
    task = asyncio.create_task(r.serve(r.device))
    try:
        yield r
    finally:
        await r.client.close()
        await asyncio.wait_for(task, 2)


# ---------------------------------------------------------------------- deadline checks
def check_window(times: list[float], expected: float) -> bool:
    """Never early; True once a run fitted in [expected, expected + MARGIN_S]."""
    assert times[-1] >= expected - EARLY_S, (
        f"gave up after {times[-1] * 1e3:.1f} ms, before its {expected * 1e3:.1f} ms deadline")
    return times[-1] <= expected + MARGIN_S


def fail_late(times: list[float], expected: float) -> None:
    pytest.fail(f"gave up {min(times) * 1e3 - expected * 1e3:.1f} ms after its "
                f"{expected * 1e3:.1f} ms deadline at best (runs: "
                f"{', '.join(f'{t * 1e3:.1f}' for t in times)} ms; margin {MARGIN_S * 1e3:.0f} ms)")


async def assert_gives_up_on_time(call: Callable[[], Awaitable[None]], expected: float) -> None:
    """``call`` (which asserts its own timeout outcome) takes ``expected`` s, on time.

    Up to REPEATS runs; each must not end early, the fastest must end within MARGIN_S.
    """
    times: list[float] = []
    for _ in range(REPEATS):
        t0 = time.monotonic()
        await call()
        times.append(time.monotonic() - t0)
        if check_window(times, expected):
            return
    fail_late(times, expected)
