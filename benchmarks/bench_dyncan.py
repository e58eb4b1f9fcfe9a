"""DYN CAN client speed and bus load, measured in the same run.

1. Transactions/s (status reads) of the servobus client against a virtual node in-process on
   python-can's virtual bus, vs python-can's raw round trip (blocking ``send`` + ``recv``)
   against the very same node on the same bus. Target >= 80 %.
2. At the 1 Mbit/s bit-timing model: the share of bus time 8 axes streaming Position Direct
   at 500 Hz take - from the model (frame bits incl. worst-case stuffing) and as measured by
   the node side's bus accounting while the client streams for real.

Run: ``python -m benchmarks`` (all) or ``python -m benchmarks.bench_dyncan``.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import can

from benchmarks.breakdown import Breakdown, loops, print_all, profile_async, profile_sync, run_on
from benchmarks.can_floor import floor_round_trips
from benchmarks.verdict import mark, percent, summary
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import open_can_client
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.protocols.dyncan.server import serve
from servobus.sim.dmm.drive import VirtualDrive
from servobus.transport.can_bus import AsyncCanBus, BitTiming

ROUND_TRIPS = 5000
ROUNDS = 5
STREAM_AXES = 8
STREAM_HZ = 500
STREAM_SECONDS = 1.0
PD_STEP = 300  # command units per period: a 2-byte Position Direct frame


@contextmanager
def node_thread(channel: str, ids: tuple[int, ...],
                timing: BitTiming | None = None
                ) -> Iterator[tuple[DynCanNetwork, list[AsyncCanBus]]]:
    """Virtual nodes on their own event loop thread (as a separate device would be)."""
    network = DynCanNetwork([VirtualDrive(i) for i in ids])
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    stop: asyncio.Event | None = None
    ports: list[AsyncCanBus] = []

    async def run() -> None:
        nonlocal stop
        stop = asyncio.Event()
        port = await AsyncCanBus.open(f"virtual:{channel}", timing=timing)
        ports.append(port)
        ready.set()
        await serve(network, port, stop=stop)
        await port.close()

    thread = threading.Thread(target=lambda: loop.run_until_complete(run()), daemon=True)
    thread.start()
    ready.wait(5)
    try:
        yield network, ports
    finally:
        assert stop is not None
        loop.call_soon_threadsafe(stop.set)
        thread.join(5)
        loop.close()



def raw_round_trips(channel: str, n: int) -> float:
    bus = can.Bus(interface="virtual", channel=channel)
    ident, data = c.encode(c.request(1, DmmFunction.READ_DRIVE_STATUS))
    msg = can.Message(arbitration_id=ident, data=data, is_extended_id=False)
    try:
        for _ in range(50):  # warm-up
            bus.send(msg)
            bus.recv(1.0)
        t = time.perf_counter()
        for _ in range(n):
            bus.send(msg)
            reply = bus.recv(1.0)
            assert reply is not None and reply.arbitration_id == ident
        return n / (time.perf_counter() - t)
    finally:
        bus.shutdown()


async def python_can_asyncio_round_trips(channel: str, n: int) -> float:
    """python-can's documented asyncio pattern: Notifier(loop=...) + AsyncBufferedReader."""
    bus = can.Bus(interface="virtual", channel=channel)
    reader = can.AsyncBufferedReader()
    notifier = can.Notifier(bus, [reader], timeout=0.1, loop=asyncio.get_running_loop())
    ident, data = c.encode(c.request(1, DmmFunction.READ_DRIVE_STATUS))
    msg = can.Message(arbitration_id=ident, data=data, is_extended_id=False)
    try:
        for _ in range(50):
            bus.send(msg)
            await reader.get_message()
        t = time.perf_counter()
        for _ in range(n):
            bus.send(msg)
            await asyncio.wait_for(reader.get_message(), 1.0)
        return n / (time.perf_counter() - t)
    finally:
        notifier.stop()
        bus.shutdown()


async def client_round_trips(channel: str, n: int) -> float:
    """``drive_status()``: one READ_DRIVE_STATUS transaction, as the raw figure's (since
    issue 18 ``status()`` also reads the speed when no profile runs: two transactions).
    A generous deadline: a reply late on a loaded host counts in the rate, not fatal."""
    client = await open_can_client(f"virtual:{channel}", timeout=1.0)
    axis = DynCanAxis(client, 1)
    try:
        for _ in range(50):
            await axis.drive_status()
        t = time.perf_counter()
        for _ in range(n):
            await axis.drive_status()
        return n / (time.perf_counter() - t)
    finally:
        await client.close()


async def client_breakdown(channel: str, label: str) -> Breakdown:
    client = await open_can_client(f"virtual:{channel}", timeout=1.0)  # profiled: slower
    axis = DynCanAxis(client, 1)
    try:
        return await profile_async(label, axis.drive_status)
    finally:
        await client.close()


def raw_breakdown(channel: str) -> Breakdown:
    bus = can.Bus(interface="virtual", channel=channel)
    ident, data = c.encode(c.request(1, DmmFunction.READ_DRIVE_STATUS))
    msg = can.Message(arbitration_id=ident, data=data, is_extended_id=False)

    def once() -> None:
        bus.send(msg)
        bus.recv(1.0)

    try:
        return profile_sync("python-can raw send+recv", once)
    finally:
        bus.shutdown()


def bench_transactions() -> tuple[float, float, float, float, dict[str, float]]:
    """Best of ROUNDS interleaved rounds per method: the machine is shared and noisy.
    (raw, python-can asyncio, asyncio floor, servobus, servobus on the other loops)."""
    channel = "servobus-bench-dyncan-rt"
    raw = aio = floor = ours = 0.0
    n = ROUND_TRIPS // ROUNDS
    ident, data = c.encode(c.request(1, DmmFunction.READ_DRIVE_STATUS))
    fast = {name: 0.0 for name, _ in loops()[1:]}
    with node_thread(channel, (1,)):
        for _ in range(ROUNDS):
            raw = max(raw, raw_round_trips(channel, n))
            aio = max(aio, asyncio.run(python_can_asyncio_round_trips(channel, n)))
            floor = max(floor, asyncio.run(floor_round_trips(channel, ident, data, n)))
            ours = max(ours, asyncio.run(client_round_trips(channel, n)))
            for name, factory in loops()[1:]:
                fast[name] = max(fast[name], run_on(factory, client_round_trips(channel, n)))
    return raw, aio, floor, ours, fast


async def _stream(channel: str) -> tuple[float, int, int]:
    client = await open_can_client(f"virtual:{channel}")
    ticks = int(STREAM_SECONDS * STREAM_HZ)
    try:
        t = time.perf_counter()
        stats = await client.stream_position_direct(
            {i: [PD_STEP] * ticks for i in range(1, STREAM_AXES + 1)}, 1 / STREAM_HZ)
        return time.perf_counter() - t, stats.frames, stats.late_cycles
    finally:
        await client.close()


def bench_stream_load() -> None:
    timing = BitTiming(1_000_000)
    dlc = len(c.encode(c.request(1, c.Function.POSITION_DIRECT, PD_STEP))[1])
    model_share = STREAM_AXES * STREAM_HZ * timing.frame_time(dlc)
    channel = "servobus-bench-dyncan-pd"
    with node_thread(channel, tuple(range(1, STREAM_AXES + 1)), timing) as (network, ports):
        elapsed, frames, late = asyncio.run(_stream(channel))
        deadline = time.monotonic() + 2
        while network.stats.frames < frames and time.monotonic() < deadline:
            time.sleep(0.01)
        received = network.stats.frames
        pacer = ports[0].pacer
        assert pacer is not None
        busy_s = pacer.busy_s  # the node side's accounting of every frame it saw
    measured_share = busy_s / elapsed
    print(f"PD streaming, {STREAM_AXES} axes x {STREAM_HZ} Hz, {dlc}-byte frames "
          f"({timing.frame_bits(dlc)} bits incl. worst-case stuffing, "
          f"{timing.frame_time(dlc) * 1e6:.0f} us at 1 Mbit/s):")
    print(f"  model: {model_share * 100:.1f} % of bus time")
    print(f"  streamed {frames} frames in {elapsed:.3f} s ({late} late tick(s)); node received "
          f"{received}: {measured_share * 100:.1f} % of bus time")


def main() -> None:
    raw, aio, floor, ours, fast = bench_transactions()
    channel = "servobus-bench-dyncan-uv"
    with node_thread(channel, (1,)):
        profiles = [run_on(factory, client_breakdown(channel, f"servobus {name} drive_status()"))
                    for name, factory in loops()]
        profiles.append(raw_breakdown(channel))
    print(f"DYN CAN status reads on python-can's virtual bus (best of {ROUNDS} x "
          f"{ROUND_TRIPS // ROUNDS}, same node):")
    print(f"  python-can raw send+recv (blocking):   {raw:8.0f} transactions/s")
    print(f"  python-can asyncio (Notifier+reader):  {aio:8.0f} transactions/s")
    print(f"  asyncio floor (a future per frame):    {floor:8.0f} transactions/s  "
          f"= {floor / raw * 100:.0f} % of raw (no protocol, no transaction rules)")
    verdict = mark("dyncan: client transactions vs python-can raw", ours / raw, at_least=0.8,
                   show=percent)
    print(f"  servobus client (asyncio, full rules): {ours:8.0f} transactions/s  "
          f"= {ours / raw * 100:.0f} % of raw {verdict}, "
          f"{ours / aio * 100:.0f} % of python-can asyncio, {ours / floor * 100:.0f} % of the "
          "floor")
    for name, rate in fast.items():
        verdict = mark(f"dyncan: client transactions vs python-can raw ({name})", rate / raw,
                       at_least=0.8, show=percent)
        print(f"  servobus client on {name}:            {rate:8.0f} transactions/s  "
              f"= {rate / raw * 100:.0f} % of raw {verdict}")
    print_all(profiles)
    bench_stream_load()


if __name__ == "__main__":
    main()
    print(summary())
