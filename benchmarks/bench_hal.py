"""servobus hal: the period, latency and jitter of the component's loop (issue 37).

For each link kind, one ``hal = "position"`` axis on an in-process virtual drive paced like
its wire (38,400 baud serial lines, the 1 Mbit/s CAN bit-timing model, EtherNet/IP over
loopback), run by the component's own loop (servobus.hal.bridge.Bridge) with a dict in
place of HAL's pins (HAL's shared-memory pin access costs well under a microsecond; what is
measured is everything after it). A producer plays LinuxCNC's servo thread: every 1 ms it
writes the next position-cmd of a sine (90 deg, 0.5 Hz) and the watchdog. Figures:

* period: the time between two target updates sent to the drive (p50 / p99) - the rate
  the link reaches - and its jitter (p99 - p50); on EasyCan, whose axis streams the 2 ms
  synchronous cache (Capability.CYCLIC_POSITION), the time between two cycles taking
  their target, and how many cycles the stream skipped (a cycle whose slot passed by more
  than 1.5 ms is skipped, not sent late: servobus.protocols.easycan.sync);
* cmd -> drive: from the moment a position-cmd value was written to the moment the update
  carrying it was handed to the link (p50 / p99); on EasyCan, to the moment a cycle took
  it (its frame goes out at that cycle's slot, within 2 ms);
* drive -> fb: from the moment the position read was sent to the moment position-fb holds
  its answer (p50 / p99): how old position-fb is when written.

Run: ``python -m benchmarks hal`` (``--seconds S`` per link, default 3).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import logging
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.verdict import mark
from servobus.hal.bridge import Bridge
from servobus.hal.pins import AXIS_PINS, COMPONENT_PINS, Pins, axis_pin
from servobus.machine import open_machine_async

KINDS: dict[str, str] = {
    "EasyCan (1 Mbit/s model)": "sim://easycan",
    "DYN CAN (1 Mbit/s model)": "sim://dyncan",
    "DYN232M (38,400 baud)": "sim://dyn232",
    "Modbus RTU (38,400 baud)": "sim://modbus",
    "DYN5 EtherNet/IP (loopback)": "sim://enip",
}
#: What a userspace loop should reach on a CAN bus: a target update every 10 ms at p99
#: (LinuxCNC's own userspace Modbus components poll far slower).
PERIOD_TARGET_S = 0.010
#: EasyCan's cyclic stream: one cycle every 2 ms; p99 - p50 of the interval within 1 ms.
JITTER_TARGET_S = 0.001


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, math.ceil(q * len(ordered)) - 1)]


def machine_text(url: str) -> str:
    return (f'[axes.a]\nurl = "{url}"\nid = 1\nunit = "deg"\nspeed = 720.0\n'
            f'accel = 7200.0\nhal = "position"\n')


async def measure(url: str, seconds: float) -> dict[str, list[float]]:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hal.toml"
        path.write_text(machine_text(url), encoding="utf-8")
        machine = await open_machine_async(path)
    axis = machine["a"]
    pins: Pins = {p.name: (0.0 if p.kind == "float" else False) for p in COMPONENT_PINS}
    for p in AXIS_PINS:
        pins[axis_pin("a", p.name)] = {"float": 0.0, "bit": False, "s32": 0}[p.kind]
    written: dict[float, float] = {}  # position-cmd value -> when it was written
    sends: list[float] = []
    to_drive: list[float] = []
    to_fb: list[float] = []
    stream_target, readings = axis.stream_target, axis.readings

    async def timed_stream(target: float, speed: float) -> None:
        await stream_target(target, speed)
        now = time.perf_counter()
        sends.append(now)
        if target in written:
            to_drive.append(now - written[target])

    async def timed_readings():  # type: ignore[no-untyped-def]
        began = time.perf_counter()
        result = await readings()
        to_fb.append(time.perf_counter() - began)  # the pin is written right after
        return result

    axis.stream_target = timed_stream  # type: ignore[method-assign]
    axis.readings = timed_readings  # type: ignore[method-assign]
    bridge = Bridge([axis], pins, watchdog_s=1.0)
    next_cyclic = bridge.axes[0].next_cyclic

    def timed_cycle() -> float | None:  # a cyclic stream's cycle takes its target
        target = next_cyclic()
        now = time.perf_counter()
        sends.append(now)
        if target is not None and target in written:
            to_drive.append(now - written[target])
        return target

    bridge.axes[0].next_cyclic = timed_cycle  # type: ignore[method-assign]
    task = asyncio.create_task(bridge.run())
    try:
        pins["watchdog"] = True
        while pins["fault"]:
            await asyncio.sleep(0.01)
        pins["a.enable"] = True
        while not bridge.axes[0].streaming:
            await asyncio.sleep(0.01)
        phase, end = 0.0, time.perf_counter() + seconds
        while time.perf_counter() < end:  # LinuxCNC's servo thread, 1 ms
            phase += 2 * math.pi * 0.5 * 0.001
            value = 90.0 * math.sin(phase)
            pins["a.position-cmd"] = value
            written[value] = time.perf_counter()
            pins["watchdog"] = not pins["watchdog"]
            await asyncio.sleep(0.001)
        if bridge.axes[0].latched:
            raise RuntimeError(bridge.axes[0].latched)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        await bridge.stop()
        await machine.close()
    periods = [b - a for a, b in itertools.pairwise(sends)]
    stats = bridge.axes[0].cyclic_stats
    skipped = [float(stats.skipped), float(stats.cycles)] if stats is not None else []
    return {"period": periods, "to_drive": to_drive, "to_fb": to_fb, "skipped": skipped}


def ms(values: list[float], q: float) -> str:
    return f"{percentile(values, q) * 1000:6.2f}"


async def run(seconds: float) -> None:
    print(f"servobus hal: one position axis per link, a 1 kHz sine command for {seconds:g} s; "
          "p50 / p99 in ms")
    for name, url in KINDS.items():
        figures = await measure(url, seconds)
        period = figures["period"]
        jitter = percentile(period, 0.99) - percentile(period, 0.5)
        line = (f"  {name:28s} period {ms(period, 0.5)} / {ms(period, 0.99)}  "
                f"jitter {jitter * 1000:6.2f}  cmd->drive {ms(figures['to_drive'], 0.5)} / "
                f"{ms(figures['to_drive'], 0.99)}  drive->fb {ms(figures['to_fb'], 0.5)} / "
                f"{ms(figures['to_fb'], 0.99)}  ({len(period) + 1} updates, "
                f"{statistics.mean(period) and 1 / statistics.mean(period):.0f}/s)")
        if figures["skipped"]:
            skipped, cycles = figures["skipped"]
            line += (f"  cyclic: {cycles:.0f} cycles sent, {skipped:.0f} skipped "
                     f"(late)  " + mark("hal EasyCan 2 ms cycle jitter p99",
                                        jitter, at_most=JITTER_TARGET_S,
                                        show=lambda s: f"{s * 1000:g} ms"))
        elif url == "sim://dyncan":
            line += "  " + mark("hal period DYN CAN p99", percentile(period, 0.99),
                                at_most=PERIOD_TARGET_S, show=lambda s: f"{s * 1000:g} ms")
        print(line)


def main(argv: list[str] | None = None) -> None:
    logging.getLogger("servobus.hal").setLevel(logging.ERROR)  # its event lines: not figures
    parser = argparse.ArgumentParser(prog="python -m benchmarks hal")
    parser.add_argument("--seconds", type=float, default=3.0)
    args, _ = parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    asyncio.run(run(args.seconds))


if __name__ == "__main__":
    main()
