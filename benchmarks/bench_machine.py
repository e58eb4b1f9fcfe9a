"""Machine: the start skew of ``move_together`` on each kind of link (issue 20).

For each link kind, a machine of two axes on in-process virtual drives (paced like the real
wire: 38,400 baud serial lines, the 1 Mbit/s CAN bit-timing model) makes REPEATS moves
together; the figure is the measured start skew (``TogetherReport.skew_s``: the latest minus
the earliest moment a start was handed to its link) and how long the whole start took.
Where the two axes share a synchronised start (DYN CAN Sync_Trigger, EasyCan sync signal)
one trigger starts both: the skew is 0 by construction and the real spread is the trigger's
own frame time on the bus (one frame, or the EasyCan signal frames back to back).
"Handed to the link" is all a host can know of a move (docs/axis.md): on DYN232M and DYN CAN
that is the write, on Modbus RTU the write's reply (so the second axis on one Modbus line
starts a round trip after the first).

Run: ``python -m benchmarks machine`` or ``python -m benchmarks.bench_machine``.
"""

from __future__ import annotations

import asyncio
import statistics
import tempfile
import time
from pathlib import Path

from benchmarks.verdict import mark
from servobus.machine import open_machine_async

REPEATS = 20
#: Links with no synchronised start: two axes started concurrently should still start within
#: two frame times of a paced 38,400 baud line (~ 2 x 2.6 ms); target for those.
GATHER_TARGET_S = 0.010

#: Kinds whose move is a write with a reply on a half-duplex line: no target (the bus decides).
REPLIED = ("Modbus RTU RS-485, one line (paced)",)

KINDS: dict[str, tuple[str, str]] = {
    # name: (url of axis a, url of axis b); ids 1 and 2
    "DYN232M RS-485, one line (paced)": ("sim://dyn232", "sim://dyn232"),
    "Modbus RTU RS-485, one line (paced)": ("sim://modbus", "sim://modbus"),
    "DYN CAN, one bus (sync trigger)": ("sim://dyncan", "sim://dyncan"),
    "EasyCan, one bus (sync signal)": ("sim://easycan", "sim://easycan"),
    "two links: DYN232M + EasyCan": ("sim://dyn232", "sim://easycan"),
    "two links: DYN232M + DYN CAN": ("sim://dyn232", "sim://dyncan"),
}


def machine_text(url_a: str, url_b: str) -> str:
    return (f'[axes.a]\nurl = "{url_a}"\nid = 1\nunit = "rev"\n'
            f'[axes.b]\nurl = "{url_b}"\nid = 2\nunit = "rev"\n')


async def measure(url_a: str, url_b: str) -> tuple[list[float], list[float], bool]:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        path.write_text(machine_text(url_a, url_b), encoding="utf-8")
        machine = await open_machine_async(path)
    skews: list[float] = []
    calls: list[float] = []
    synchronised = False
    try:
        for i in range(REPEATS):
            target = 0.25 if i % 2 == 0 else 0.0
            t0 = time.perf_counter()
            report = await machine.move_together({"a": target, "b": -target})
            calls.append(time.perf_counter() - t0)
            skews.append(report.skew_s)
            synchronised = report.synchronised
            for axis in machine.axes.values():
                await axis.wait_idle(10.0)
    finally:
        await machine.close()
    return skews, calls, synchronised


async def run() -> None:
    print(f"move_together start skew, {REPEATS} moves of two axes per link kind "
          "(median / max; 'start' = the whole call)")
    for name, (url_a, url_b) in KINDS.items():
        skews, calls, synchronised = await measure(url_a, url_b)
        median, worst = statistics.median(skews), max(skews)
        line = (f"  {name:40s} skew {median * 1000:7.3f} / {worst * 1000:7.3f} ms   "
                f"start {statistics.median(calls) * 1000:6.2f} ms")
        if synchronised:
            print(line + "   one trigger")
        elif name in REPLIED:
            print(line + "   a replied write: the next start waits for the reply")
        else:
            print(line + "   " + mark(f"machine skew {name}", worst, at_most=GATHER_TARGET_S,
                                      show=lambda s: f"{s * 1000:g} ms"))


def main() -> None:
    asyncio.run(run())


if __name__ == "__main__":
    main()
