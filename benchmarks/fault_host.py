"""The fault run's machine process: a machine opened with ``retry=True`` that polls like the
GUI and the gateway do, and answers the run's questions (benchmarks/bench_faults.py).

``python -m benchmarks.fault_host MACHINE_FILE [--debug]``. Every axis is read every
:data:`POLL_S` (``readings()``: position, speed and status, as the gateway samples; the
GUI reads the same every 0.1 s). Each successful read is kept with its start and end
(``time.monotonic()``, one clock for every process on the host). servobus's log lines are
counted, and written to stderr. Questions come as JSON lines on stdin, answers go as JSON lines to
stdout, one at a time:

* ``{"cmd": "recover", "axis", "since", "timeout", "target"}`` (``since`` is after the
  fault): wait for the first fresh value - a position read that starts after ``since``,
  once the axis is online with its power check done (tried every :data:`WATCH_S`), and
  succeeds; ``online_at`` is when it returned. Then acknowledge what the axis flags, move
  it to ``target`` and read until it rests there (within ``tolerance``) or ``timeout``
  passed. Answers ``online_at``, ``power_lost``, ``interrupted``, ``position``, ``error``.
* ``{"cmd": "stale", "axis", "t0", "t1"}``: how many reads of the axis started at or after
  ``t0`` and returned a value before ``t1`` (the run's window in which nothing could
  answer).
* ``{"cmd": "cpu"}``: this process's CPU time (every thread) and the monotonic time.
* ``{"cmd": "stats"}``: log lines at INFO and above, reconnect tries, reads by outcome.
* ``{"cmd": "quit"}``: close the machine (a stop first) and exit.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import sys
import time
from collections import Counter, deque
from pathlib import Path
from typing import Any

from servobus.errors import DriveTimeout, ServobusError
from servobus.machine import open_machine_async
from servobus.machine.machine import AsyncMachine

POLL_S = 0.1
WATCH_S = 0.005
READ_DEADLINE_S = 2.0
KEEP_READS = 5000


class LineCounter(logging.Handler):
    """servobus's log lines at INFO and above, by level, with the last few texts."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.lines = 0
        self.last: deque[str] = deque(maxlen=50)

    def emit(self, record: logging.LogRecord) -> None:
        if record.name.startswith("servobus"):
            self.lines += 1
            self.last.append(f"{time.monotonic():.3f} {record.getMessage()}")


class Host:
    def __init__(self, machine: AsyncMachine, lines: LineCounter) -> None:
        self.machine = machine
        self.log = lines
        self.reads: dict[str, deque[tuple[float, float]]] = {
            name: deque(maxlen=KEEP_READS) for name in machine.axes}
        self.outcomes: Counter[str] = Counter()

    async def poll(self, name: str) -> None:
        axis = self.machine[name]
        while True:
            start = time.monotonic()
            try:
                async with asyncio.timeout(READ_DEADLINE_S):
                    await axis.readings()
            except (ServobusError, TimeoutError) as exc:
                self.outcomes[type(exc).__name__] += 1
            else:
                self.reads[name].append((start, time.monotonic()))
                self.outcomes["ok"] += 1
            await asyncio.sleep(max(0.0, start + POLL_S - time.monotonic()))

    async def recover(self, q: dict[str, Any]) -> dict[str, Any]:
        axis = self.machine[q["axis"]]
        end = time.monotonic() + q["timeout"]
        while True:  # the first fresh value: a read that started after ``since`` and worked
            if time.monotonic() >= end:
                return {"error": f"not online within {q['timeout']} s: {axis.last_error}"}
            if axis.online and not axis.checking:
                with contextlib.suppress(ServobusError):
                    await axis.position()
                    break
            await asyncio.sleep(WATCH_S)
        online_at = time.monotonic()
        answer: dict[str, Any] = {"online_at": online_at, "power_lost": axis.power_lost,
                                  "interrupted": axis.interrupted, "error": None}
        try:
            await axis.acknowledge()
            await axis.move_to(q["target"])
            answer["position"] = await self._arrival(q["axis"], q["target"], q["tolerance"],
                                                     end)
        except ServobusError as exc:
            answer["error"] = f"{type(exc).__name__}: {exc}"
        return answer

    async def _arrival(self, name: str, target: float, tolerance: float, end: float) -> float:
        """Where the axis rests once at ``target``, or where it stands at ``end``. A read that
        misses its deadline (a loaded host: the poller sees a few) is read again, as the
        CLI's ``move --wait`` does; it is counted, not a failed fault."""
        axis = self.machine[name]
        position = float("nan")
        while time.monotonic() < end:
            try:
                position, _, status = await axis.readings()
                if abs(position - target) <= tolerance and not status.moving:
                    break
            except DriveTimeout:
                self.outcomes["DriveTimeout while arriving"] += 1
            await asyncio.sleep(POLL_S)
        return position

    def stale(self, q: dict[str, Any]) -> dict[str, Any]:
        reads = self.reads[q["axis"]]
        return {"stale": sum(1 for start, end in reads if start >= q["t0"] and end < q["t1"])}

    def stats(self) -> dict[str, Any]:
        return {"log_lines": self.log.lines, "last_lines": list(self.log.last),
                "reconnect_tries": self.machine.reconnect_tries, "reads": dict(self.outcomes)}


async def answer_questions(host: Host) -> None:
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    while line := await reader.readline():
        q = json.loads(line)
        if q["cmd"] == "quit":
            return
        if q["cmd"] == "recover":
            out = await host.recover(q)
        elif q["cmd"] == "stale":
            out = host.stale(q)
        elif q["cmd"] == "cpu":
            out = {"cpu": time.process_time(), "t": time.monotonic()}
        else:
            out = host.stats()
        print(json.dumps(out), flush=True)


async def main(path: str, debug: bool) -> None:
    lines = LineCounter()
    logging.getLogger().addHandler(lines)
    to_stderr = logging.StreamHandler()  # the run keeps it with --logs
    to_stderr.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    logging.getLogger().addHandler(to_stderr)
    logging.getLogger().setLevel(logging.INFO)
    if debug:  # every reconnect try, in the log only (the counter takes INFO and above)
        logging.getLogger("servobus.machine").setLevel(logging.DEBUG)
    machine = await open_machine_async(Path(path), retry=True)
    host = Host(machine, lines)
    pollers = [asyncio.create_task(host.poll(name)) for name in machine.axes]
    print(json.dumps({"ready": sorted(n for n, a in machine.axes.items() if a.online)}),
          flush=True)
    try:
        await answer_questions(host)
    finally:
        for task in pollers:
            task.cancel()
        for task in pollers:
            with contextlib.suppress(BaseException):
                await task
        await machine.close()


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], "--debug" in sys.argv[2:]))
