"""The Class 1 production clock: a dedicated thread that sends each frame on its deadline.

Decision (issue 22): the scanner's O->T production runs on this thread, not on the event
loop it was opened on. A loop wakes up late whenever it is busy with anything else (a
reply being decoded, a user's task, the epoll selector's millisecond rounding), and it is
a user's thread: servobus may not change its scheduling. The clock thread is servobus's
own, so it may run at SCHED_FIFO (:mod:`servobus.thread_priority`) - but only when asked,
``SERVOBUS_CLOCK_REALTIME=1``: measured, a real-time clock thread once stalled O->T
production for ~0.4 s (1 run in 12, two scanner processes at once on a loaded 2-core
machine; the same runs without it never did). The likely cause is the interpreter lock:
a real-time thread that waits for it waits for a normal thread to be scheduled. A drive
whose watchdog is 16 RPIs must not meet that, so the default is the normal scheduler
(measured beside two CPU hogs, 16 connections at 5 ms: O->T p99 0.3-4 ms).

Deadlines are absolute on ``time.monotonic_ns``: frame k of a
producer is due at ``first + k * period`` (never "now + period", which drifts by every
wake-up's lateness); the thread sleeps until :data:`SPIN_NS` before the deadline and
spins the rest, so the wake-up latency of ``sleep`` does not add to the frame's (the spin
holds the interpreter lock: it is kept short, and producers of one period share one
wake-up, see :meth:`ClockThread.add`). A
producer that fell more than a period behind restarts its grid from now (no burst of
catch-up frames: the consumer wants the latest data).

A producer's ``send`` runs on the clock thread: it must be thread-safe (the scanner's
takes its connection's lock and calls ``socket.sendto``, which is).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from typing import ClassVar

from servobus.thread_priority import request_realtime

log = logging.getLogger("servobus.enip")

#: Environment variable: ``1`` runs the clock thread at SCHED_FIFO (module docstring).
CLOCK_REALTIME_ENV = "SERVOBUS_CLOCK_REALTIME"


def clock_realtime_requested() -> bool:
    return os.environ.get(CLOCK_REALTIME_ENV, "").strip().lower() in ("1", "on", "yes", "true")


#: The last stretch before a deadline is spun, not slept (a sleep may wake ~50-100 us
#: late; a spin is as late as the next time check). Short: the thread may be real-time.
SPIN_NS = 100_000
#: Producers due this close after a wake-up's deadline leave in that wake-up.
EARLY_NS = 100_000


def next_due(due_ns: int, period_ns: int, now_ns: int) -> int:
    """The deadline after ``due_ns``: one period on the grid, or - for a producer that fell
    more than a period behind - a new grid from ``now_ns``. Never accumulates lateness."""
    nxt = due_ns + period_ns
    if nxt < now_ns - period_ns:
        return now_ns + period_ns
    return nxt


class Tick:
    """One periodic production on a :class:`ClockThread` (``send()`` every period)."""

    __slots__ = ("active", "due_ns", "period_ns", "send")

    def __init__(self, period_ns: int, due_ns: int, send: Callable[[], None]) -> None:
        self.period_ns = period_ns
        self.due_ns = due_ns
        self.send = send
        self.active = True


class ClockThread:
    """Every producer of the process on one daemon thread (module docstring)."""

    _shared: ClassVar[ClockThread | None] = None
    _shared_lock: ClassVar[threading.Lock] = threading.Lock()

    def __init__(self, *, realtime: bool = False, now_ns: Callable[[], int] = time.monotonic_ns,
                 name: str = "servobus-clock"
                 ) -> None:
        self.realtime = realtime
        self.granted = False  # SCHED_FIFO was granted to the thread
        self.late_restarts = 0
        self._now = now_ns
        self._ticks: list[Tick] = []
        self._cond = threading.Condition()
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._started = False
        self._name = name

    @classmethod
    def shared(cls) -> ClockThread:
        """The process's clock (started on first use); SCHED_FIFO only when
        ``SERVOBUS_CLOCK_REALTIME=1`` (module docstring: opt-in)."""
        with cls._shared_lock:
            if cls._shared is None or cls._shared._stopped:
                cls._shared = cls(realtime=clock_realtime_requested())
            return cls._shared

    def add(self, period_s: float, send: Callable[[], None]) -> Tick:
        """Produce with ``send()`` every ``period_s``, the first frame now - or, when a
        producer of the same period runs already, on its next deadline: producers of one
        period share their wake-ups (16 connections at 5 ms: one wake-up per 5 ms, not
        16; the thread spins and takes the interpreter lock once per period)."""
        period_ns = round(period_s * 1e9)
        with self._cond:
            same = [t.due_ns for t in self._ticks if t.period_ns == period_ns]
        tick = Tick(period_ns, min(same) if same else self._now(), send)
        with self._cond:
            self._ticks.append(tick)
            if not self._started:
                self._started = True
                self._thread.start()
            self._cond.notify()
        return tick

    def remove(self, tick: Tick) -> None:
        with self._cond:
            tick.active = False
            if tick in self._ticks:
                self._ticks.remove(tick)
            self._cond.notify()

    def __len__(self) -> int:
        with self._cond:
            return len(self._ticks)

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._cond.notify()
        if self._started and threading.current_thread() is not self._thread:
            self._thread.join(2.0)

    # ------------------------------------------------------------- the thread
    def _run(self) -> None:
        if self.realtime:
            self.granted = request_realtime(f"Class 1 clock thread {self._name!r}")
        while self.step():
            pass

    def step(self) -> bool:
        """Wait for the earliest deadline and send what is due (one pass; False once
        stopped). Runs on the clock thread; a test may call it on a fake clock."""
        with self._cond:
            while not self._ticks and not self._stopped:
                self._cond.wait()
            if self._stopped:
                return False
            due = min(t.due_ns for t in self._ticks)
            left = due - self._now() - SPIN_NS
            if left > 0:
                # woken early by add/remove: re-evaluate the earliest deadline
                self._cond.wait(left / 1e9)
                return True
        while self._now() < due:  # the final spin, outside the lock
            pass
        with self._cond:
            ticks = [t for t in self._ticks if t.active and t.due_ns <= due + EARLY_NS]
        for tick in ticks:
            try:
                tick.send()
            except Exception:  # a producer's fault must not stop every other one
                log.exception("Class 1 producer failed; it is stopped")
                self.remove(tick)
                continue
            now = self._now()
            nxt = next_due(tick.due_ns, tick.period_ns, now)
            if nxt != tick.due_ns + tick.period_ns:
                self.late_restarts += 1
            tick.due_ns = nxt
        return True
