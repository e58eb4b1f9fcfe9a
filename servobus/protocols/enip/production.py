"""Cyclic production on one timer: every T->O connection of the adapters on one event loop.

Decision (issue 10 benchmarks): one timer (``loop.call_at``) serves every periodic producer
on a loop, armed for the earliest due time, instead of one timer handle per frame. Each
producer keeps an absolute grid: the next frame is due one period after the previous one's
*due* time, not after when it left, so a late wake-up does not shift the grid; a producer
that fell more than a period behind restarts its grid from now (no burst of catch-up frames,
the consumer wants the latest data). Frames due within :data:`EARLY_S` of a wake-up leave in
that wake-up. The wheel knows nothing about EtherNet/IP: a producer is a period and a
callback.

Precision is the event loop's: asyncio's default selector on Linux (epoll) sleeps in whole
milliseconds, rounded up, so a frame can leave up to 1 ms late; ``servobus sim enip`` runs
its loop on select(), which sleeps in microseconds (``servobus.protocols.enip.cli``).
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import weakref
from collections.abc import Callable
from typing import ClassVar

#: Frames due this close after a wake-up leave in it (one pass for close neighbours).
EARLY_S = 0.0001


class Producer:
    """One periodic production: ``send()`` every ``period_s`` from ``first_at`` (loop time)."""

    __slots__ = ("active", "next_at", "period_s", "send")

    def __init__(self, period_s: float, first_at: float, send: Callable[[], None]) -> None:
        self.period_s = period_s
        self.next_at = first_at
        self.send = send
        self.active = True


class ProductionWheel:
    """Every producer of one event loop on one timer (module docstring)."""

    _wheels: ClassVar[weakref.WeakKeyDictionary[asyncio.AbstractEventLoop,
                                                ProductionWheel]] = weakref.WeakKeyDictionary()

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._heap: list[tuple[float, int, Producer]] = []
        self._order = itertools.count()
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = 0.0
        self.late_restarts = 0  # producers that fell more than a period behind

    @classmethod
    def for_loop(cls, loop: asyncio.AbstractEventLoop) -> ProductionWheel:
        wheel = cls._wheels.get(loop)
        if wheel is None:
            wheel = cls._wheels[loop] = cls(loop)
        return wheel

    def __len__(self) -> int:
        return sum(1 for _, _, p in self._heap if p.active)

    def add(self, producer: Producer) -> Producer:
        heapq.heappush(self._heap, (producer.next_at, next(self._order), producer))
        self._arm()
        return producer

    def remove(self, producer: Producer) -> None:
        """Stop it; its heap entry is dropped when it comes up (no search)."""
        producer.active = False

    def _arm(self) -> None:
        heap = self._heap
        while heap and not heap[0][2].active:
            heapq.heappop(heap)
        if not heap:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            return
        due = heap[0][0]
        if self._timer is not None:
            if self._timer_at <= due:
                return
            self._timer.cancel()
        self._timer_at = due
        self._timer = self._loop.call_at(due, self._fire)

    def _fire(self) -> None:
        self._timer = None
        heap = self._heap
        loop = self._loop
        now = loop.time()
        while heap and heap[0][0] <= now + EARLY_S:
            _, _, producer = heapq.heappop(heap)
            if not producer.active:
                continue
            producer.send()
            if not producer.active:  # the callback stopped it
                continue
            period = producer.period_s
            due = producer.next_at + period
            if due < now - period:
                due = loop.time() + period
                self.late_restarts += 1
            producer.next_at = due
            heapq.heappush(heap, (due, next(self._order), producer))
        self._arm()
