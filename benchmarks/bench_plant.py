"""Plant: how many axes one gateway serves at 50 Hz within half a core, the number to plan a
plant of gateways with (issue 36, item 6).

One gateway (servobus.gateway.serve.Gateway, as ``servobus serve --mqtt ... --sparkplug
plant`` runs it) in this process, with its machine of N virtual axes on N fast links
(``servobus sim ... --fast --plant ideal`` servers in their own processes, one drive each;
DYN232M, DYN CAN and EasyCan links in turn). Every axis turns at constant speed, so its
position changes at every sample (its speed and current too with ``--plant physics``,
below). Sampling 50 Hz; an observer in another process subscribes with asyncua to every
ActualPosition (publishing interval 20 ms) and with aiomqtt to the Sparkplug topics; MQTT
JSON state and Sparkplug DDATA at ``--mqtt-rate`` (default here 5 Hz, the gateway's
default; ``python -m benchmarks plant --mqtt-rate 50`` for the worst case). For N = 2, 4, 6,
8 (``--axes``), over 8 s: the CPU of this process (the gateway and its links' clients, %
of one core), the axis samples it took (counted per axis by a sampler listener), the rate
its slowest link reached over those seconds (its axes' samples per second), its CPU and
OPC UA writes per sample, the CPU of the drives' processes and of the observer, and the
load average.

Why one drive per link (decision): at the sampler's duty of 0.5 a link keeps 50 Hz only
while a round of its drives takes at most 10 ms (docs/gateway.md "Sampling"). With 8
drives a link (bench_gateway's layout, this benchmark's before) a DYN232M round is 32
round trips to the drives' process one after another, and no run reached 45 Hz on this
machine whatever the gateway's CPU; with 2 drives a link, 4 axes reached 41.5 - 43 Hz at
load averages of 7 - 8, with one 46.9 - 50 Hz at 7 - 11 (2 and 4 axes). One drive a link (an
EtherNet/IP drive, a bus of its own) also gives the gateway the fewest samples per
wake-up: its CPU per sample is the dearest, the safe side to plan on. ``--per-link N``
measures another layout.

The figure (decision): the straight line through (axis samples per second, CPU %) of the
runs whose every link reached 45 Hz: its intercept is what the gateway spends whatever the
rate (the OPC UA server's and MQTT clients' own upkeep), its slope what one axis sample costs,
and the axes per half core is where it reaches 50 % at 50 samples per axis per second (with
every link at 50 Hz, the line through (axes, CPU %)). Slower runs are printed, with their CPU
per sample, but give no figure: on a machine too loaded for the links to keep 50 Hz the
gateway's CPU per sample was 950 - 3,500 us (load averages 17 - 22 on 2 cores): fewer
samples per wake-up, caches shared with the load. A figure from such runs would plan a
plant wrong. The figure's line names the runs it comes from, their conditions and their
load, and says when the line reaches half a core beyond the largest run.
``--axes 2,4`` chooses the runs, ``--plant physics`` the drives' plant, ``--per-link N``
the drives on each link, ``--profile FILE`` profiles the gateway's process over the
measured seconds (CPU time, cProfile; ``python -m pstats FILE``).

Why the ideal plant (decision): with their physics (4 kHz per drive, docs/virtual-drive.md)
48 turning drives cost about a core of their own, and on a 2-core machine they starved the
gateway: with 16 axes it sampled at 21.8 Hz and no run reached the old 45 Hz floor. ``--plant
ideal`` drives answer the same protocol with the same readings (a turning shaft, exactly its
reference) at next to no CPU, so the machine's cores are left to the gateway being measured.
The drives' and the observer's CPU are printed so that a reader sees what else ran. What it
changes for the gateway: a cruising ideal shaft's speed is exact and its current 0, so a
sample changes one OPC UA value (the position), where a physical drive's jittering speed and
current change more (1.7 writes per sample with 16 physics axes against 1.0 with ideal ones,
at load averages of 17 - 20), and Sparkplug's DDATA by exception carries fewer metrics. The
table counts the OPC UA writes per sample; ``--plant physics`` runs the
drives with their physics (``--axes 16`` where the machine has room for them) to measure
what the other writes cost. The figure from ideal drives is therefore the upper bound of a
plant whose drives report a steady speed and current.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import cProfile
import math
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from benchmarks.bench_dyn232_line import cpu_seconds
from benchmarks.bench_gateway import broker

RATE_HZ = 50.0
PER_LINK = 1
COUNTS = (2, 4, 6, 8)
MEASURE_S = 8.0
GROUP = "plant"
#: (protocol of ``servobus sim``, URL scheme, unit, per_rev), taken in turn per link
LINKS = [("dyn232", "dyn232+socket", "mm", 5.0), ("dyncan", "dyncan+socketcand", "mm", 5.0),
         ("easycan", "easycan+socketcand", "deg", None)]
MIN_HZ = 45.0
HALF_CORE = 50.0


@contextlib.contextmanager
def drive_servers(links: int, per_link: int = PER_LINK, plant: str = "ideal"
                  ) -> Iterator[tuple[list[str], list[int]]]:
    """``links`` drive servers of ``per_link`` drives each (``--plant``): (URLs, pids)."""
    procs, urls = [], []
    try:
        for i in range(links):  # all started before any is waited for: they start together
            protocol, _, _, _ = LINKS[i % len(LINKS)]
            args = [sys.executable, "-m", "servobus", "sim", protocol, "--fast", "--plant",
                    plant, "--ids", ",".join(str(k) for k in range(1, per_link + 1))]
            if protocol == "dyn232":
                args += ["--listen", "127.0.0.1:0"]
            procs.append(subprocess.Popen(args, stdout=subprocess.PIPE,
                                          stderr=subprocess.DEVNULL, text=True))
        for i, proc in enumerate(procs):
            assert proc.stdout is not None
            address = proc.stdout.readline().split()[-1].removeprefix("tcp://")
            urls.append(f"{LINKS[i % len(LINKS)][1]}://{address}")
        yield urls, [proc.pid for proc in procs]
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:  # a loaded machine may take its time: none is left running
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def machine_toml(name: str, urls: list[str], per_link: int = PER_LINK) -> str:
    lines = [f'name = "{name}"']
    for i in range(len(urls) * per_link):
        _, _, unit, per_rev = LINKS[(i % len(urls)) % len(LINKS)]
        lines += [f"[axes.a{i:02d}]", f'url = "{urls[i % len(urls)]}"',
                  f"id = {i // len(urls) + 1}", f'unit = "{unit}"', "continuous = true"] \
            + ([f"per_rev = {per_rev}"] if per_rev else [])
    return "\n".join(lines) + "\n"


def observe(endpoint: str, mqtt_port: int, machine: str, seconds: float, out: Any,
            ready: Any) -> None:
    asyncio.run(_observe(endpoint, mqtt_port, machine, seconds, out, ready))


async def _observe(endpoint: str, mqtt_port: int, machine: str, seconds: float, out: Any,
                   ready: Any) -> None:
    import aiomqtt
    from asyncua import Client

    from servobus.gateway.opcua_model import DI_URI, ROBOTICS_URI, SERVOBUS_URI

    counts = {"opcua": 0, "ddata": 0}

    class Handler:
        def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
            counts["opcua"] += 1

    async def sparkplug() -> None:
        async with aiomqtt.Client("127.0.0.1", mqtt_port) as client:
            await client.subscribe(f"spBv1.0/{GROUP}/DDATA/#")
            async for _ in client.messages:
                counts["ddata"] += 1

    async with Client(endpoint) as client:
        di, ro, sb = [await client.get_namespace_index(u)
                      for u in (DI_URI, ROBOTICS_URI, SERVOBUS_URI)]
        axes = await client.nodes.objects.get_child(
            [f"{di}:DeviceSet", f"{ro}:MotionDeviceSystem", f"{ro}:MotionDevices",
             f"{sb}:{machine}", f"{ro}:Axes"])
        nodes = [await child.get_child([f"{di}:ParameterSet", f"{ro}:ActualPosition"])
                 for child in await axes.get_children()]
        sub = await client.create_subscription(20, Handler())
        await sub.subscribe_data_change(nodes, queuesize=1)
        task = asyncio.create_task(sparkplug())
        await asyncio.sleep(1.0)
        ready.set()
        counts.update(opcua=0, ddata=0)
        await asyncio.sleep(seconds)
        out.put(dict(counts))
        task.cancel()


async def run_one(count: int, mqtt_port: int, folder: Path, mqtt_hz: float,
                  profile: cProfile.Profile | None = None, per_link: int = PER_LINK,
                  plant: str = "ideal") -> dict[str, Any]:
    from servobus.gateway.mqtt import MqttOptions
    from servobus.gateway.opcua_server import OpcUaOptions
    from servobus.gateway.serve import Gateway, GatewayOptions
    from servobus.machine import open_machine_async

    name = f"plant-{count}"
    with drive_servers(count // per_link, per_link, plant) as (urls, pids):
        path = folder / f"{name}.toml"
        path.write_text(machine_toml(name, urls, per_link))
        machine = await open_machine_async(path)
        try:
            for axis in machine.axes.values():
                await axis.turn(2.0)
            mqtt = MqttOptions(f"mqtt://127.0.0.1:{mqtt_port}", rate_hz=mqtt_hz)
            gateway = Gateway(machine, GatewayOptions(
                OpcUaOptions("opc.tcp://127.0.0.1:0"), mqtt=mqtt, rate_hz=RATE_HZ,
                own_process=True, sparkplug=GROUP))
            samples: dict[str, int] = dict.fromkeys(machine.axes, 0)
            gateway.sampler.listeners.append(lambda sample: _count(samples, sample))
            await gateway.start()
            ctx = multiprocessing.get_context("spawn")
            out, ready = ctx.Queue(), ctx.Event()
            observer = ctx.Process(target=observe, args=(gateway.opcua.endpoint, mqtt_port,
                                                         name, MEASURE_S, out, ready))
            observer.start()
            loop = asyncio.get_running_loop()
            while not ready.is_set():
                if not observer.is_alive():
                    raise RuntimeError("the observer ended before it subscribed (its "
                                       "traceback above): a machine too loaded to measure")
                await asyncio.sleep(0.05)
            others = [*pids, observer.pid or 0]
            c0, w0, n0 = time.process_time(), time.monotonic(), dict(samples)
            writes0 = gateway.opcua.notifications
            o0 = [cpu_seconds(pid) for pid in others]
            if profile is not None:
                profile.enable()
            await asyncio.sleep(MEASURE_S)
            if profile is not None:
                profile.disable()
            wall = time.monotonic() - w0
            cpu = (time.process_time() - c0) / wall
            per_axis = [samples[a] - n0[a] for a in samples]
            taken = sum(per_axis) / wall
            writes = gateway.opcua.notifications - writes0
            o1 = [cpu_seconds(pid) for pid in others]
            drives = sum(b - a for a, b in zip(o0[:-1], o1[:-1], strict=True)) / wall
            watcher = (o1[-1] - o0[-1]) / wall
            counts: dict[str, int] = await loop.run_in_executor(None, out.get, True, 30)
            await loop.run_in_executor(None, observer.join, 10)
            await gateway.close()
        finally:
            await machine.close()
    # every axis of a link has a sample per round: the slowest axis is the slowest link
    return {"count": count, "cpu": cpu * 100, "hz": min(per_axis) / wall, "samples": taken,
            "load": os.getloadavg()[0],
            "writes": writes / (taken * wall) if taken else math.nan,
            "drives": drives * 100, "observer": watcher * 100, **counts}


def _count(samples: dict[str, int], sample: Any) -> None:
    if sample.ok:
        samples[sample.axis] += 1


def fit(points: list[tuple[float, float]]) -> tuple[float, float]:
    """(intercept, slope) of the least-squares line through ``points``."""
    n = len(points)
    mx = sum(x for x, _ in points) / n
    my = sum(y for _, y in points) / n
    slope = sum((x - mx) * (y - my) for x, y in points) / sum((x - mx) ** 2 for x, _ in points)
    return my - slope * mx, slope


def per_half_core(points: list[tuple[float, float]]) -> float:
    """Axes at :data:`RATE_HZ` within half a core, from (axis samples/s, CPU %) points: where
    their least-squares line reaches 50 %, in axes of RATE_HZ samples per second."""
    base, per_sample = fit(points)
    return (HALF_CORE - base) / per_sample / RATE_HZ


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks plant")
    parser.add_argument("--mqtt-rate", type=float, default=5.0)
    parser.add_argument("--axes", default=",".join(map(str, COUNTS)), metavar="2,4,6,8",
                        type=lambda text: [int(n) for n in text.split(",")],
                        help="the runs' axis counts (multiples of --per-link)")
    parser.add_argument("--per-link", type=int, default=PER_LINK, metavar="N",
                        help="drives per link (fewer: more links, each round shorter)")
    parser.add_argument("--plant", choices=("ideal", "physics"), default="ideal",
                        help="the drives' plant (servobus sim --plant)")
    parser.add_argument("--profile", metavar="FILE", type=Path,
                        help="profile the gateway's process in the measured seconds of every "
                             "run (cProfile); the statistics go to FILE (pstats)")
    args, _ = parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    if args.per_link < 1 or any(n <= 0 or n % args.per_link for n in args.axes):
        parser.error(f"--axes {args.axes}: give multiples of --per-link {args.per_link}")
    print(f"plant: one gateway at {RATE_HZ:g} Hz (OPC UA + MQTT JSON + Sparkplug B at "
          f"{args.mqtt_rate:g} Hz), every axis turning; {drives_per_link(args.per_link)}, "
          f"--plant {args.plant}; drives and observer in other processes")
    print(f"  {os.cpu_count()} cores, load average {load_average()} before")
    print("  axes  gateway CPU  axis samples/s  slowest link  CPU per sample  OPC UA writes "
          "per sample  drives CPU  observer CPU  OPC UA notif./s  DDATA/s  load")
    results = []
    # CPU time, not wall time: the waits in epoll are not the gateway's cost
    profile = cProfile.Profile(time.process_time) if args.profile else None
    with tempfile.TemporaryDirectory() as tmp, broker(Path(tmp)) as mqtt_port:
        if mqtt_port is None:
            print("  mosquitto is not installed: no figure")
            return
        for count in args.axes:
            r = asyncio.run(run_one(count, mqtt_port, Path(tmp), args.mqtt_rate, profile,
                                    args.per_link, args.plant))
            results.append(r)
            per_sample = r["cpu"] / 100 / r["samples"] * 1e6 if r["samples"] else math.nan
            print(f"  {count:4d}  {r['cpu']:9.1f} %  {r['samples']:14.0f}  {r['hz']:9.1f} Hz"
                  f"  {per_sample:11.0f} us  {r['writes']:24.1f}"
                  f"  {r['drives']:8.1f} %  {r['observer']:10.1f} %"
                  f"  {r['opcua'] / MEASURE_S:15.0f}  {r['ddata'] / MEASURE_S:7.0f}"
                  f"  {r['load']:4.1f}")
    print(f"  load average {load_average()} after")
    if profile is not None:
        profile.dump_stats(args.profile)
        print(f"  profile of the gateway's process: {args.profile} (python -m pstats)")
    print(figure(results, f"{drives_per_link(args.per_link)}, --plant {args.plant}, MQTT and "
                          f"Sparkplug at {args.mqtt_rate:g} Hz"))


def drives_per_link(n: int) -> str:
    return "1 drive per link" if n == 1 else f"{n} drives per link"


def figure(results: list[dict[str, Any]], conditions: str) -> str:
    """The figure's line: from the runs whose slowest link reached :data:`MIN_HZ` (never
    from slower ones, module docstring), with its conditions and the load it was taken at."""
    kept = [r for r in results if r["hz"] >= MIN_HZ]
    points = [(r["samples"], r["cpu"]) for r in kept]
    if len(points) < 2 or len({x for x, _ in points}) < 2:
        # no estimate from slower runs (decision, module docstring): the CPU per sample of
        # a loaded machine is not the gateway's cost
        return (f"  fewer than two runs reached {MIN_HZ:g} Hz on every link (the load of "
                "this machine: see the load average and the drives' CPU): no figure")
    base, slope = fit(points)
    axes = per_half_core(points)  # no target in the issue: the figure to plan with
    counts = sorted(r["count"] for r in kept)
    loads = sorted(r["load"] for r in kept)
    where = ("beyond the largest run: the line says so, no run of that size was measured"
             if axes > counts[-1] else "within the runs measured")
    return (f"  axes per half core at {RATE_HZ:g} Hz: {axes:.0f}  (the line through the "
            f"{len(kept)} runs of {', '.join(map(str, counts))} axes whose every link "
            f"reached {MIN_HZ:g} Hz: {base:.1f} % + {slope * 1e4:.0f} us per axis sample; "
            f"{conditions}; load average {loads[0]:.1f} - {loads[-1]:.1f}; {where})")


def load_average() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


if __name__ == "__main__":
    main()
