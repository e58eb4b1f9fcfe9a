"""Samples of one axis for the scope and the step test, at the rate the link allows.

Where the drive keeps its own trace (``AsyncAxis.trace_buffer``, e.g. the 4 kHz trace of a
virtual drive) the sampler reads it every :data:`TRACE_READ_S` and the samples carry the
drive's own times. Elsewhere it polls the Axis (position, and speed, current and status only
when a channel shows them), stamping each sample with the middle of its reads; the rate is
what the link gives, capped at :data:`POLL_MAX_HZ` so a fast in-process link does not eat
a core. Sampling runs while someone subscribes and stops :data:`LINGER_S` after the last
one left.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import logging
import operator
import time
from array import array
from collections import deque
from collections.abc import Iterable

from servobus.axis.capabilities import Capability
from servobus.errors import ConnectionLost, ServobusError
from servobus.gui.fleet import AxisHandle
from servobus.gui.ring import SampleRing
from servobus.gui.signals import BIT_SIGNALS, POLLED_READS, SIGNALS

log = logging.getLogger(__name__)

TRACE_READ_S = 0.008
POLL_MAX_HZ = 1000.0
LINGER_S = 1.0
#: The longest scope window; the ring keeps it plus a margin at a 4 kHz trace's rate.
MAX_WINDOW_S = 20.0
CAPACITY = int((MAX_WINDOW_S + 2.0) * 4000)
RATE_SPAN_S = 1.0


@functools.lru_cache(maxsize=64)
def _offsets(n: int, rate_hz: float) -> tuple[float, ...]:
    """0, 1/rate, 2/rate, ...: the sample times of a trace chunk from its first sample."""
    return tuple(i / rate_hz for i in range(n))


class AxisSampler:
    def __init__(self, handle: AxisHandle) -> None:
        self.handle = handle
        self.ring = SampleRing(CAPACITY)
        self.source = "unknown"  # "trace" or "poll" once known
        self.rate_hz = 0.0
        self.error = ""
        self.lost = 0
        self._wanted: dict[int, frozenset[str]] = {}
        self._tokens = itertools.count(1)
        self._task: asyncio.Task[None] | None = None
        self._idle_since: float | None = None
        self._poll_times: deque[float] = deque()

    # ------------------------------------------------------------- subscriptions
    def subscribe(self, signals: Iterable[str]) -> int:
        token = next(self._tokens)
        self._wanted[token] = frozenset(s for s in signals if s in SIGNALS)
        self._idle_since = None
        if self._task is None or self._task.done():
            if self.error.startswith("sampling stopped"):
                self.error = ""  # a new try
            self._task = asyncio.create_task(self._run(), name=f"gui-sampler-{self.handle.id}")
        return token

    def unsubscribe(self, token: int) -> None:
        self._wanted.pop(token, None)
        if not self._wanted:
            self._idle_since = time.monotonic()

    @property
    def wanted(self) -> frozenset[str]:
        return frozenset().union(*self._wanted.values()) if self._wanted else frozenset()

    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    def describe(self) -> dict[str, object]:
        return {"axis": self.handle.id, "source": self.source, "rate_hz": self.rate_hz,
                "running": self.running, "error": self.error, "lost": self.lost,
                "samples": len(self.ring)}

    # ------------------------------------------------------------- acquisition
    def _lingered(self) -> bool:
        return (not self._wanted and self._idle_since is not None
                and time.monotonic() - self._idle_since > LINGER_S)

    async def _run(self) -> None:
        """Trace where the drive keeps one, else poll; any failure of the trace falls back
        to polling, and whatever ends the sampling is in :attr:`error` (the page shows it)."""
        try:
            if self.source != "poll":
                try:
                    if self.handle.axis.supports(Capability.DRIVE_TRACE):
                        await self.handle.axis.trace_buffer()  # starts the drive's recording
                        self.source = "trace"
                    else:
                        self.source = "poll"
                except ConnectionLost:
                    raise
                except Exception as exc:  # a trace that cannot start: poll instead
                    self._fall_back(exc)
            if self.source == "trace":
                try:
                    await self._run_trace()
                    return
                except ConnectionLost:
                    raise
                except Exception as exc:  # a trace that fails: poll from now on
                    self._fall_back(exc)
            await self._run_poll()
        except ConnectionLost as exc:
            self.error = f"sampling stopped: link lost: {exc}"
        except Exception as exc:  # never silent: the scope's status line shows it
            self.error = f"sampling stopped: {type(exc).__name__}: {exc}"
            log.error("GUI sampler of %s: %s", self.handle.label, self.error)

    def _fall_back(self, exc: Exception) -> None:
        self.error = f"trace: {type(exc).__name__}: {exc}; polling instead"
        self.source = "poll"
        log.warning("GUI sampler of %s: %s", self.handle.label, self.error)

    async def _run_trace(self) -> None:
        axis = self.handle.axis
        while not self._lingered():
            await asyncio.sleep(TRACE_READ_S)
            cap = await axis.trace_buffer()
            n = cap.count
            self.lost += cap.lost
            if not n:
                continue
            self.rate_hz = cap.rate_hz
            times = array("d", map(operator.add, _offsets(n, cap.rate_hz),
                                   itertools.repeat(cap.t0, n)))
            values = {name: cap.signals[name] for name in ("position", "position_error",
                                                           "speed", "current")
                      if name in cap.signals}
            status = cap.signals.get("status")
            if status is not None:
                for name in BIT_SIGNALS:
                    bit = SIGNALS[name].bit
                    assert bit is not None
                    values[name] = array("d", (float(int(v) >> bit & 1) for v in status))
            self.ring.extend(times, values)

    async def _run_poll(self) -> None:
        h = self.handle
        axis = h.axis
        min_period = 1.0 / POLL_MAX_HZ
        while not self._lingered():
            wanted = self.wanted or frozenset({"position"})
            t0 = time.monotonic()
            values: dict[str, float] = {}
            try:
                for name, call in POLLED_READS.items():
                    if name in wanted or name == "position":
                        values[name] = float(await h.call(getattr(axis, call)()))
                if wanted & set(BIT_SIGNALS):
                    st = await h.call(axis.status())
                    values.update({"enabled": float(st.enabled), "moving": float(st.moving),
                                   "in_position": float(st.in_position),
                                   "alarm": float(st.alarm)})
                if not self.error.startswith("trace:"):  # keep saying why it polls
                    self.error = ""
            except ConnectionLost:
                raise
            except ServobusError as exc:
                self.error = f"{type(exc).__name__}: {exc}"
                await asyncio.sleep(0.05)
                continue
            t1 = time.monotonic()
            self.ring.append((t0 + t1) / 2, values)
            self._poll_times.append(t1)
            while self._poll_times and self._poll_times[0] < t1 - RATE_SPAN_S:
                self._poll_times.popleft()
            span = t1 - self._poll_times[0] if len(self._poll_times) > 1 else 0.0
            self.rate_hz = (len(self._poll_times) - 1) / span if span > 0 else 0.0
            await asyncio.sleep(max(0.0, min_period - (t1 - t0)))
