"""Where a transaction's time goes: the per-transaction breakdown the benchmarks print.

Two measures that hold on a loaded machine (wall time does not): the CPU time of this
process per transaction (``time.process_time``, no profiler attached: what the client and
its event loop cost), and, from one profiled run (cProfile), counts per transaction -
Python function calls, event-loop passes (``_run_once``: one wake-up each), selector
waits (``epoll.poll``/``select``), futures and tasks created, thread hand-offs, socket
system calls, log records - and the share of profiled own time per layer:

* ``loop``      asyncio's own machinery (loop passes, handles, futures, selector transport)
* ``syscall``   socket send/recv and the selector wait (kernel time is CPU time too)
* ``link``      servobus.link: the transaction rules (deadlines, lanes, late replies)
* ``protocol``  servobus.protocols: framing, encoding, decoding
* ``axis``      servobus.axis / families: the Axis API, units, status
* ``transport`` servobus.transport: streams, trace hooks
* ``threads``   threading / concurrent.futures: the sync facade's hop to the loop thread
* ``logging``   the logging module (a disabled ``log.debug`` still costs a call)
* ``other``     everything else (the benchmark's own loop, builtins)

Used by bench_enip, bench_dyn232_client and bench_dyncan (each prints its paths' lines).
"""

from __future__ import annotations

import asyncio
import cProfile
import pstats
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TypeVar

T = TypeVar("T")

LAYERS = ("loop", "syscall", "link", "protocol", "axis", "transport", "threads", "logging",
          "other")


@dataclass
class Breakdown:
    label: str
    n: int
    cpu_us: float  # process CPU time per transaction, unprofiled
    calls: float = 0.0  # Python function calls per transaction
    counts: dict[str, float] = field(default_factory=dict)
    shares: dict[str, float] = field(default_factory=dict)  # of profiled own time

    def lines(self) -> list[str]:
        c = self.counts
        head = (f"  breakdown per transaction, {self.label}: {self.cpu_us:.1f} us CPU, "
                f"{self.calls:.0f} calls, {c['loop passes']:.2f} loop passes, "
                f"{c['selector waits']:.2f} selector waits, {c['futures']:.2f} futures, "
                f"{c['tasks']:.2f} tasks, {c['thread hand-offs']:.2f} thread hand-offs, "
                f"{c['socket calls']:.2f} socket calls, {c['log calls']:.2f} log calls")
        parts = ", ".join(f"{k} {v:.0%}" for k, v in self.shares.items() if v >= 0.005)
        return [head, f"    own time by layer: {parts}"]


def _layer(filename: str, name: str) -> str:
    f = filename.replace("\\", "/")
    if filename == "~":
        if any(s in name for s in ("poll", "select", "send", "recv", "epoll")):
            return "syscall"
        if "_asyncio" in name or "Future" in name or "Task" in name:
            return "loop"
        return "other"
    for key, layer in (("/servobus/link/", "link"), ("/servobus/protocols/", "protocol"),
                       ("/servobus/axis/", "axis"), ("/servobus/families/", "axis"),
                       ("/servobus/transport/", "transport"), ("/asyncio/", "loop"),
                       ("/selectors.py", "loop"), ("/threading.py", "threads"),
                       ("/concurrent/futures/", "threads"), ("/queue.py", "threads"),
                       ("/logging/", "logging"), ("/uvloop/", "loop")):
        if key in f:
            return layer
    return "other"


def _analyse(prof: cProfile.Profile, n: int, label: str, cpu_us: float) -> Breakdown:
    stats = pstats.Stats(prof)
    raw = stats.stats  # type: ignore[attr-defined]
    own = dict.fromkeys(LAYERS, 0.0)
    total_calls = 0
    counts = dict.fromkeys(("loop passes", "selector waits", "futures", "tasks",
                            "thread hand-offs", "socket calls", "log calls"), 0.0)
    for (filename, _line, name), (_cc, ncalls, tt, _ct, _callers) in raw.items():
        total_calls += ncalls
        own[_layer(filename, name)] += tt
        if name == "_run_once":
            counts["loop passes"] += ncalls
        elif filename == "~" and ("poll' of 'select" in name or "'select' of 'select" in name
                                  or "epoll" in name):
            counts["selector waits"] += ncalls
        elif name in ("create_future", "run_coroutine_threadsafe"):
            counts["futures"] += ncalls
            if name == "run_coroutine_threadsafe":
                counts["thread hand-offs"] += ncalls
        elif name == "create_task":
            counts["tasks"] += ncalls
        elif filename == "~" and any(s in name for s in ("'send' of", "'recv' of",
                                                           "'sendall' of", "'recv_into' of",
                                                           "'sendto' of", "'recvfrom' of")):
            counts["socket calls"] += ncalls
        elif "/logging/" in filename and name in ("debug", "info", "isEnabledFor", "log"):
            counts["log calls"] += ncalls
        elif filename.endswith("threading.py") and name in ("wait", "set"):
            counts["thread hand-offs"] += ncalls / 2  # a hop: one set and one wait
    total = sum(own.values()) or 1.0
    return Breakdown(label, n, cpu_us, total_calls / n,
                     {k: v / n for k, v in counts.items()},
                     {k: v / total for k, v in own.items()})


async def profile_async(label: str, call: Callable[[], Awaitable[object]], n: int = 2000
                        ) -> Breakdown:
    """``n`` awaits of ``call()`` on the running loop: CPU per call, then a profiled run."""
    for _ in range(min(200, n)):
        await call()
    t0 = time.process_time()
    for _ in range(n):
        await call()
    cpu_us = (time.process_time() - t0) / n * 1e6
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(n):
        await call()
    prof.disable()
    return _analyse(prof, n, label, cpu_us)


def profile_sync(label: str, call: Callable[[], object], n: int = 2000) -> Breakdown:
    """The same for a blocking call (e.g. the sync Axis facade). CPU time counts every
    thread of this process (the facade's loop thread too); cProfile sees this thread only,
    so the calls and layers of a sync facade call are the caller's side of the hop."""
    for _ in range(min(200, n)):
        call()
    t0 = time.process_time()
    for _ in range(n):
        call()
    cpu_us = (time.process_time() - t0) / n * 1e6
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(n):
        call()
    prof.disable()
    return _analyse(prof, n, label, cpu_us)


def print_all(items: list[Breakdown]) -> None:
    for item in items:
        for line in item.lines():
            print(line)




def loops() -> list[tuple[str, Callable[[], asyncio.AbstractEventLoop]]]:
    """The loops a figure is shown on: asyncio's, and uvloop's when installed."""
    out: list[tuple[str, Callable[[], asyncio.AbstractEventLoop]]] = [
        ("asyncio", asyncio.new_event_loop)]
    try:
        import uvloop
    except ImportError:
        return out
    out.append(("uvloop", uvloop.new_event_loop))
    return out


def run_on(factory: Callable[[], asyncio.AbstractEventLoop],
           main: Awaitable[T]) -> T:
    """``asyncio.run(main)`` on a loop from ``factory``."""
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(main)  # type: ignore[arg-type]

