"""EtherNet/IP (DYN5): explicit round trips and Class 1 implicit I/O, measured in one run.

1. Explicit messaging: Get_Attribute_Single round trips/s (Parameter 0x1D, motor position)
   against the same virtual DYN5 (``servobus sim enip`` in its own process), one request at
   a time: the servobus client on asyncio's loop and on uvloop (when installed), the sync
   Axis facade (its calls on the caller's thread, and on a loop thread as before),
   pycomm3's ``CIPDriver.generic_message`` (unconnected, ``route_path=False``)
   and a raw blocking socket with a prebuilt request (the ceiling: no client work at all).
   Rounds alternate; the best round of each counts. Targets: one at a time >= 1.0 x pycomm3
   (per loop), 8 in flight >= 1.5 x pycomm3. Then the per-transaction breakdown
   (benchmarks/breakdown.py) of each path.
2. Implicit I/O: 1, 4 and 16 adapters (127.0.0.1 .., one process) x 1 connection at RPI
   5 ms, scanner (the servobus ``CyclicIo``) in this process, idle-ish and beside two
   CPU-bound processes (started here, killed by PID after), with real-time scheduling
   (SCHED_FIFO for the adapters' loop) and without. Per run:
   T->O frames delivered, p50/p99/max of |interval - RPI| at the scanner's socket (the
   kernel's receive time) and of the O->T frames at the scanner's ``sendto``. The 16-adapter
   runs with SCHED_FIFO carry the targets (delivered >= 99.9 %, p99 <= 1 ms); a run without
   it that misses 1 ms says so (docs/enip.md: what to configure).

The machine's load is printed first: other work on the host shows in these figures.
Run: ``python -m benchmarks enip`` or ``python -m benchmarks.bench_enip``.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import os
import socket
import statistics
import struct
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from benchmarks.breakdown import Breakdown, loops, print_all, profile_async, profile_sync, run_on
from benchmarks.verdict import mark, percent, summary
from servobus.axis import connect, connect_async, inline
from servobus.fastloop import fast_available
from servobus.protocols.enip.axis import EnipAxis
from servobus.protocols.enip.client import AsyncEnipClient
from servobus.protocols.enip.clock import ClockThread
from servobus.protocols.enip.scanner import InputFrame

PARAM, POSITION, ATTRIBUTE = 0x0F, 0x1D, 1
ROUND_S = 1.0
#: Interleaved rounds per explicit figure, the best of each kept: beside CPU-bound work a
#: client's rate swings by a third from round to round (pycomm3 8.3k-12.6k reads/s in two
#: runs beside two hogs), so three rounds could leave one side at an unlucky best.
ROUNDS = 5
IN_FLIGHT = 8
IO_ADAPTERS = 16
IO_RPI_MS = 5.0
IO_SECONDS = 5.0
IO_SETTLE_S = 1.0  # after every connection is open, before the measured window


@contextmanager
def adapters(count: int, seconds: float, *, realtime: bool = True
             ) -> Iterator[tuple[subprocess.Popen[str], list[tuple[str, int]]]]:
    """``servobus sim enip`` on 127.0.0.1 .. 127.0.0.<count> in its own process."""
    hosts = ",".join(f"127.0.0.{i}" for i in range(1, count + 1))
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "enip", "--listen",
                             hosts, "--tcp-port", "0", "--udp-port", "0", "--duration",
                             str(seconds), "--realtime" if realtime else "--no-realtime"],
                            stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    found: list[tuple[str, int]] = []
    try:
        while len(found) < count:
            line = proc.stdout.readline()
            if not line:
                raise RuntimeError("servobus sim enip did not start")
            address = line.split("enip://", 1)[1].split()[0]
            host, port = address.rsplit(":", 1)
            found.append((host, int(port)))
        yield proc, found
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU time of a process (Linux /proc), None elsewhere."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


# ---------------------------------------------------------------- explicit
async def servobus_rate(host: str, port: int, seconds: float, in_flight: int = 1) -> float:
    """``in_flight`` tasks reading on one session with ``max_in_flight=in_flight``."""
    client = await AsyncEnipClient.connect(host, port, max_in_flight=in_flight)
    done = [0]
    t0 = 0.0

    async def reader() -> None:
        while time.perf_counter() - t0 < seconds:
            await client.get_attribute_single(PARAM, POSITION, ATTRIBUTE)
            done[0] += 1

    try:
        for _ in range(200):
            await client.get_attribute_single(PARAM, POSITION, ATTRIBUTE)
        t0 = time.perf_counter()
        await asyncio.gather(*(reader() for _ in range(in_flight)))
        return done[0] / (time.perf_counter() - t0)
    finally:
        await client.close()


class _Floor(asyncio.Protocol):
    """A bare asyncio protocol: one future per reply, no framing beyond the length."""

    def __init__(self) -> None:
        self.waiter: asyncio.Future[bytes] | None = None
        self.buf = b""

    def data_received(self, data: bytes) -> None:
        self.buf += data
        if len(self.buf) >= 24 and len(self.buf) >= 24 + struct.unpack_from("<H", self.buf, 2)[0]:
            packet, self.buf = self.buf, b""
            if self.waiter is not None and not self.waiter.done():
                self.waiter.set_result(packet)


async def asyncio_floor_rate(host: str, port: int, seconds: float) -> float:
    """The same request bytes over a bare asyncio protocol: what any asyncio client pays."""
    loop = asyncio.get_running_loop()
    transport, proto = await loop.create_connection(_Floor, host, port)

    async def exchange(packet: bytes) -> bytes:
        proto.waiter = loop.create_future()
        transport.write(packet)
        return await proto.waiter

    try:
        reply = await exchange(struct.pack("<HHII8sI", 0x65, 4, 0, 0, bytes(8), 0)
                               + b"\x01\x00\x00\x00")
        packet = _request_packet(struct.unpack_from("<I", reply, 4)[0])
        for _ in range(200):
            await exchange(packet)
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            await exchange(packet)
            n += 1
        return n / (time.perf_counter() - t0)
    finally:
        transport.close()


def _request_packet(session: int) -> bytes:
    mr = bytes((0x0E, 3, 0x20, PARAM, 0x24, POSITION, 0x30, ATTRIBUTE))
    data = struct.pack("<IHHHHHH", 0, 0, 2, 0, 0, 0xB2, len(mr)) + mr
    return struct.pack("<HHII8sI", 0x6F, len(data), session, 0, b"rawbench", 0) + data


def pycomm3_rate(host: str, port: int, seconds: float) -> float:
    from pycomm3 import DINT, CIPDriver

    with CIPDriver(f"{host}:{port}") as plc:
        def read() -> None:
            tag = plc.generic_message(service=0x0E, class_code=PARAM, instance=POSITION,
                                      attribute=ATTRIBUTE, data_type=DINT, connected=False,
                                      route_path=False)
            if tag.error:
                raise RuntimeError(f"pycomm3: {tag.error}")

        for _ in range(200):
            read()
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            read()
            n += 1
        return n / (time.perf_counter() - t0)


def _recv_packet(sock: socket.socket) -> bytes:
    head = b""
    while len(head) < 24:
        head += sock.recv(24 - len(head))
    (length,) = struct.unpack_from("<H", head, 2)
    body = b""
    while len(body) < length:
        body += sock.recv(length - len(body))
    return head + body


def raw_rate(host: str, port: int, seconds: float) -> float:
    """Blocking socket, request bytes built once: the round-trip ceiling of this adapter."""
    with socket.create_connection((host, port), timeout=5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(struct.pack("<HHII8sI", 0x65, 4, 0, 0, bytes(8), 0) + b"\x01\x00\x00\x00")
        packet = _request_packet(struct.unpack_from("<I", _recv_packet(sock), 4)[0])
        for _ in range(200):
            sock.sendall(packet)
            _recv_packet(sock)
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            sock.sendall(packet)
            _recv_packet(sock)
            n += 1
        return n / (time.perf_counter() - t0)


def bench_explicit() -> None:
    runs = [(f"servobus {name}", factory) for name, factory in loops()]
    names = ("raw socket", "asyncio floor", "pycomm3", *(n for n, _ in runs),
             "servobus sync", "sync, loop thread", f"servobus x{IN_FLIGHT}")
    best = dict.fromkeys(names, 0.0)
    with adapters(1, ROUNDS * len(names) * (ROUND_S + 1) + 60) as (_, [(host, port)]):
        for _ in range(ROUNDS):
            rates = [raw_rate(host, port, ROUND_S),
                     asyncio.run(asyncio_floor_rate(host, port, ROUND_S)),
                     pycomm3_rate(host, port, ROUND_S)]
            rates += [run_on(factory, servobus_rate(host, port, ROUND_S))
                      for _, factory in runs]
            rates += [sync_rate(host, port, ROUND_S),
                      sync_rate(host, port, ROUND_S, thread=True),
                      asyncio.run(servobus_rate(host, port, ROUND_S, IN_FLIGHT))]
            for name, rate in zip(names, rates, strict=True):
                best[name] = max(best[name], rate)
        profiles = explicit_breakdowns(host, port, runs)
    ceiling = best["raw socket"]
    notes = {"raw socket": "blocking socket, prebuilt request: the ceiling",
             "asyncio floor": "bare asyncio protocol, prebuilt request",
             "pycomm3": "CIPDriver.generic_message, one at a time",
             "servobus asyncio": "AsyncEnipClient on asyncio's loop, one at a time",
             "servobus uvloop": "AsyncEnipClient on uvloop, one at a time",
             "servobus sync": "sync Axis.position(), inline: on the calling thread",
             "sync, loop thread": f"the same with SERVOBUS_SYNC=thread ({_facade_loop()})",
             f"servobus x{IN_FLIGHT}": f"{IN_FLIGHT} tasks, max_in_flight={IN_FLIGHT}, one "
                                      "session"}
    for name, rate in best.items():
        print(f"explicit Get_Attribute_Single, {name:>16}: {rate:8.0f}/s "
              f"({rate / ceiling:6.1%} of the raw socket; {notes[name]})")
    print_all(profiles)
    for name, _ in runs:
        one = best[name] / best["pycomm3"]
        floor = best[name] / best["asyncio floor"]
        verdict = mark(f"enip: {name} one at a time vs pycomm3", one, at_least=1.0,
                       show="{:g}x".format)
        print(f"one at a time: {name} / pycomm3 = {one:.2f}x  {verdict}; / asyncio floor "
              f"= {floor:.0%}")
    print(f"one at a time: asyncio floor / pycomm3 = "
          f"{best['asyncio floor'] / best['pycomm3']:.2f}x (the most any client on asyncio's "
          "loop can reach; below 1 the target is out of reach on this loop)")
    print(f"one at a time: servobus sync facade / pycomm3 = "
          f"{best['servobus sync'] / best['pycomm3']:.2f}x on the calling thread, "
          f"{best['sync, loop thread'] / best['pycomm3']:.2f}x with a hop to a loop thread "
          "and back")
    ratio = best[f"servobus x{IN_FLIGHT}"] / best["pycomm3"]
    verdict = mark(f"enip: servobus ({IN_FLIGHT} in flight) vs pycomm3 round trips", ratio,
                   at_least=1.5, show="{:g}x".format)
    print(f"servobus ({IN_FLIGHT} in flight) / pycomm3 = {ratio:.2f}x  {verdict}")


def _facade_loop() -> str:
    return "uvloop" if fast_available() else "asyncio"


@contextmanager
def _sync_mode(thread: bool) -> Iterator[None]:
    """``SERVOBUS_SYNC=thread`` (``thread``) or unset while a facade is opened."""
    old = os.environ.get(inline.ENV)
    os.environ[inline.ENV] = "thread" if thread else ""
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(inline.ENV, None)
        else:
            os.environ[inline.ENV] = old


def sync_rate(host: str, port: int, seconds: float, *, thread: bool = False) -> float:
    """The sync Axis facade (what a script calls): ``position()`` one at a time; ``thread``:
    on a loop thread (``SERVOBUS_SYNC=thread``) instead of the caller's."""
    with _sync_mode(thread), connect(f"enip://{host}:{port}") as axis:
        for _ in range(200):
            axis.position()
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            axis.position()
            n += 1
        return n / (time.perf_counter() - t0)


def explicit_breakdowns(host: str, port: int,
                        runs: list[tuple[str, Callable[[], asyncio.AbstractEventLoop]]]
                        ) -> list[Breakdown]:
    """Per transaction: the async client on each loop, the sync facade, pycomm3."""
    out: list[Breakdown] = []

    async def client(label: str) -> Breakdown:
        c = await AsyncEnipClient.connect(host, port)
        try:
            return await profile_async(label, lambda: c.get_attribute_single(
                PARAM, POSITION, ATTRIBUTE))
        finally:
            await c.close()

    for name, factory in runs:
        out.append(run_on(factory, client(f"{name} get_attribute_single")))
    for thread in (False, True):
        where = f"loop thread, {_facade_loop()}" if thread else "inline"
        with _sync_mode(thread), connect(f"enip://{host}:{port}") as axis:
            out.append(profile_sync(f"servobus sync Axis.position() ({where})",
                                    axis.position))
    from pycomm3 import DINT, CIPDriver
    with CIPDriver(f"{host}:{port}") as plc:
        out.append(profile_sync("pycomm3 generic_message", lambda: plc.generic_message(
            service=0x0E, class_code=PARAM, instance=POSITION, attribute=ATTRIBUTE,
            data_type=DINT, connected=False, route_path=False)))
    return out


# ---------------------------------------------------------------- implicit
@dataclass
class Recorder:
    times: list[float] = field(default_factory=list)  # in the scanner's Python
    wire: list[float] = field(default_factory=list)  # at the socket (kernel receive time)
    sequences: list[int] = field(default_factory=list)
    recording: bool = True  # off at the end of the window (closing takes time)

    def __call__(self, frame: InputFrame) -> None:
        if not self.recording:
            return
        self.times.append(frame.time)
        self.wire.append(frame.wire_time)
        self.sequences.append(frame.sequence)

    def clear(self) -> None:
        self.times.clear()
        self.wire.clear()
        self.sequences.clear()


def interval_errors_ms(series: list[list[float]], rpi: float) -> list[float]:
    return [abs(b - a - rpi) * 1e3 for times in series
            for a, b in itertools.pairwise(times)]


def p99(values: list[float]) -> float:
    return statistics.quantiles(values, n=100)[98] if len(values) > 100 else float("inf")


@dataclass
class IoRun:
    recorders: list[Recorder]
    sends: list[list[float]]  # O->T send times per connection, on the clock thread
    wall: float
    scanner_cpu: float
    adapter_cpu: float | None
    losses: int


async def run_scanner(endpoints: list[tuple[str, int]], adapter_pid: int,
                      seconds: float = IO_SECONDS) -> IoRun:
    axes: list[EnipAxis] = []
    for host, port in endpoints:
        axis = await connect_async(f"enip://{host}:{port}", timeout=1.0)
        assert isinstance(axis, EnipAxis)
        axes.append(axis)
    recorders = [Recorder() for _ in axes]
    ios = [axis.io(rpi_ms=IO_RPI_MS, on_frame=rec) for axis, rec in
           zip(axes, recorders, strict=True)]
    sends: list[list[float]] = [[] for _ in ios]
    for cyclic, times in zip(ios, sends, strict=True):
        await cyclic.open()
        _record_sends(cyclic, times)
    await asyncio.sleep(IO_SETTLE_S)
    for rec, times in zip(recorders, sends, strict=True):
        rec.clear()
        times.clear()
    cpu0, wall0, child0 = time.process_time(), time.monotonic(), cpu_seconds(adapter_pid)
    await asyncio.sleep(seconds)
    cpu1, wall1, child1 = time.process_time(), time.monotonic(), cpu_seconds(adapter_pid)
    for rec in recorders:
        rec.recording = False
    sends = [list(times) for times in sends]
    losses = sum(c.stats.losses for c in ios)
    for cyclic in ios:
        await cyclic.close()
    for axis in axes:
        await axis.close()
    wall = wall1 - wall0
    child = None if child0 is None or child1 is None else (child1 - child0) / wall
    return IoRun(recorders, sends, wall, (cpu1 - cpu0) / wall, child, losses)


def _record_sends(cyclic: object, times: list[float]) -> None:
    """Stamp each O->T datagram as it is handed to the socket (on the clock thread)."""
    udp = cyclic._udp  # type: ignore[attr-defined]
    send = udp.sendto

    def stamped(data: bytes | bytearray, addr: tuple[str, int]) -> None:
        times.append(time.monotonic())
        send(data, addr)

    udp.sendto = stamped


@contextmanager
def cpu_hogs(count: int) -> Iterator[list[int]]:
    """``count`` CPU-bound processes beside the run; killed by their PIDs after."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
             for _ in range(count)]
    try:
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            p.kill()
            p.wait(10)


def _spread(errors: list[float]) -> str:
    if len(errors) < 101:
        return "too few intervals"
    q = statistics.quantiles(errors, n=100)
    return f"p50 {q[49]:.3f} ms, p99 {q[98]:.3f} ms, max {max(errors):.2f} ms"


def implicit_case(count: int, realtime: bool, hogs: int, seconds: float,
                  marked: bool) -> None:
    """One run: ``count`` adapters, real-time scheduling of the adapters' loop on or off,
    beside ``hogs`` CPU-bound processes. The scanner's clock thread runs as configured
    (default scheduler unless SERVOBUS_CLOCK_REALTIME=1, servobus/protocols/enip/clock.py)."""
    # each connection loss is counted in the run's line: not one warning per loss as well
    logging.getLogger("servobus.enip").setLevel(logging.ERROR)
    with cpu_hogs(hogs), adapters(count, seconds + IO_SETTLE_S + 60,
                                  realtime=realtime) as (proc, endpoints):
        run = asyncio.run(run_scanner(endpoints, proc.pid, seconds))
    clock_rt = ClockThread.shared().granted
    rpi = IO_RPI_MS / 1e3
    expected = count * run.wall / rpi
    delivered = sum(len(r.times) for r in run.recorders)
    ratio = min(delivered / expected, 1.0)
    sched = "adapters at SCHED_FIFO" if realtime else "adapters at the default scheduler"
    sched += ", scanner clock " + ("SCHED_FIFO" if clock_rt else "default")
    where = f"{count} adapter(s), {sched}, {hogs} CPU hog(s)"
    wire = interval_errors_ms([r.wire for r in run.recorders], rpi)
    ours = interval_errors_ms(run.sends, rpi)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"implicit I/O, {where}, RPI {IO_RPI_MS:g} ms, {run.wall:.1f} s, load {load:.2f}: "
          f"{delivered / expected:.3%} of T->O frames, {run.losses} losses; CPU scanner "
          f"{run.scanner_cpu:.1%}, adapters "
          f"{'n/a' if run.adapter_cpu is None else f'{run.adapter_cpu:.1%}'}")
    worst = p99(wire) if wire else float("inf")
    line = f"  T->O interval error at the scanner's socket: {_spread(wire)}"
    if marked:
        line += "  " + mark(f"enip: implicit p99 interval error at the socket, {where} (ms)",
                            worst, at_most=1.0)
        verdict = mark(f"enip: implicit frames delivered, {where}", ratio, at_least=0.999,
                       show=percent)
        print(f"  delivered {delivered / expected:8.3%}  {verdict}")
    print(line)
    print(f"  O->T interval error at the scanner's sendto (clock thread): {_spread(ours)}")
    if not realtime and worst > 1.0:
        print("  -> without real-time scheduling this host cannot hold 1 ms: see docs/enip.md "
              "(run as root or grant CAP_SYS_NICE / RLIMIT_RTPRIO)")
    if not clock_rt and ours and p99(ours) > 1.0:
        print("  -> O->T beyond 1 ms: the scanner's clock thread runs at the default scheduler "
              "(SERVOBUS_CLOCK_REALTIME=1 where permitted; docs/enip.md, Class 1 timing)")


def bench_implicit() -> None:
    """1, 4 and 16 adapters, idle-ish and beside two CPU hogs, SCHED_FIFO on and off; the
    16-adapter runs with SCHED_FIFO (the default) carry the targets."""
    for hogs in (0, 2):
        for count in (1, 4, IO_ADAPTERS):
            for realtime in (True, False):
                implicit_case(count, realtime, hogs,
                              IO_SECONDS if count == IO_ADAPTERS else IO_SECONDS / 2,
                              marked=count == IO_ADAPTERS and realtime)


def main() -> None:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"EtherNet/IP benchmarks (load average {load[0]:.2f}, {os.cpu_count()} cores)")
    bench_explicit()
    bench_implicit()


if __name__ == "__main__":
    main()
    print(summary())
