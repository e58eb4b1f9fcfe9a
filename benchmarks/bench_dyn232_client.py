"""DYN232M client speed against the physical limits, measured in the same run.

1. Position polls/s through the paced in-process line (38400 8N1) vs the wire limit for the
   same bytes (baud / 10 / bytes per poll). Target >= 97 %.
2. Full parameter read (8 parameters + config + status) on the paced line. Target <= 25 ms;
   the wire time of the same bytes is printed beside it.
3. Unpaced round trips/s over TCP to ``servobus sim dyn232 --fast`` (own process) vs a raw
   socket echo server (own process, same event-loop type) answering the same byte counts.
   Target >= 80 %. Beside it, in the same rounds, the ceilings that bound it: a raw blocking
   client against the simulator (no client work at all) and a protocol-free asyncio client
   against the echo and the simulator (what asyncio alone leaves).

Run: ``python -m benchmarks`` (all) or ``python -m benchmarks.bench_dyn232_client``.
"""

from __future__ import annotations

import asyncio
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

from benchmarks.breakdown import Breakdown, loops, print_all, profile_async, run_on
from benchmarks.verdict import mark, percent, summary
from servobus.axis import connect_async
from servobus.families.dmm import params as P
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.transport.trace import ByteCounter

POLL_SECONDS = 2.0
PARAM_READS = 20
TCP_ROUND_TRIPS = 2000
TCP_ROUNDS = 7

_ECHO_SERVER = """
import asyncio, sys
async def handle(reader, writer):
    try:
        while data := await reader.read(4096):
            writer.write(data)
    except ConnectionError:
        pass
async def main():
    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    print("listening on tcp://127.0.0.1:%d" % server.sockets[0].getsockname()[1], flush=True)
    await asyncio.sleep(float(sys.argv[1]))
asyncio.run(main())
"""


_REPLY_SERVER = """
import asyncio, sys
REPLY = bytes.fromhex(sys.argv[2])
async def handle(reader, writer):
    buf = b""
    while data := await reader.read(4096):
        buf += data
        while len(buf) >= 4:
            buf = buf[4:]
            writer.write(REPLY)
async def main():
    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    print("listening on tcp://127.0.0.1:%d" % server.sockets[0].getsockname()[1], flush=True)
    await asyncio.sleep(float(sys.argv[1]))
asyncio.run(main())
"""


async def _open_paced() -> tuple[Dyn232Axis, ByteCounter]:
    core = await connect_async("sim://dyn2")
    assert isinstance(core, Dyn232Axis) and isinstance(core.client, AsyncDyn232Client)
    counter = ByteCounter()
    core.client.stream.add_trace(counter)
    return core, counter


async def paced_breakdown(label: str) -> Breakdown:
    core, _ = await _open_paced()
    try:
        return await profile_async(label, core.position, 300)
    finally:
        await core.close()


async def bench_position_polls(loop_name: str = "asyncio") -> float:
    core, counter = await _open_paced()
    try:
        await core.position()
        tx0, rx0, n = counter.tx, counter.rx, 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < POLL_SECONDS:
            await core.position()
            n += 1
        elapsed = time.perf_counter() - t0
    finally:
        await core.close()
    bytes_per_poll = (counter.tx - tx0 + counter.rx - rx0) / n
    limit = c.BAUD / c.BITS_PER_BYTE / bytes_per_poll
    rate = n / elapsed
    ratio = rate / limit
    verdict = mark(f"dyn232 client: paced position polls ({loop_name})", ratio, at_least=0.97,
                   show=percent)
    print(f"position polls, paced 38400, {loop_name}: {rate:7.1f}/s vs wire limit {limit:7.1f}/s "
          f"({bytes_per_poll:.0f} bytes/poll) = {ratio:6.1%}  {verdict}")
    return ratio


async def bench_param_read() -> float:
    core, counter = await _open_paced()
    try:
        await core.status()
        best, total = float("inf"), 0.0
        tx0, rx0 = counter.tx, counter.rx
        for _ in range(PARAM_READS):
            t0 = time.perf_counter()
            await core.read_params(P.DYN_PARAMS)
            await core.config()
            await core.status()
            dt = time.perf_counter() - t0
            best, total = min(best, dt), total + dt
    finally:
        await core.close()
    wire = c.wire_time_s((counter.tx - tx0 + counter.rx - rx0) // PARAM_READS)
    mean = total / PARAM_READS
    verdict = mark("dyn232 client: full parameter read", mean, at_most=0.025,
                   show=lambda s: f"{s * 1e3:g} ms")
    print(f"full parameter read (8 + config + status), paced 38400: mean {mean * 1e3:5.2f} ms, "
          f"best {best * 1e3:5.2f} ms, wire time {wire * 1e3:5.2f} ms "
          f"= {wire / mean:6.1%} of wire speed  {verdict}")
    return mean


@contextmanager
def _server(args: list[str]) -> Iterator[tuple[str, int]]:
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()
        if not line.startswith("listening on tcp://"):
            raise RuntimeError(f"server did not start: {line!r}")
        host, port = line.split("tcp://", 1)[1].rsplit(":", 1)
        yield host, int(port)
    finally:
        proc.terminate()
        proc.wait(10)


def _raw_echo_rate(host: str, port: int, request: bytes, reply_len: int) -> float:
    payload = request + b"\x00" * (reply_len - len(request)) if reply_len > len(request) \
        else request
    return _raw_rate(host, port, payload, len(payload))


def _raw_rate(host: str, port: int, request: bytes, reply_len: int) -> float:
    """Blocking socket, prebuilt request, the reply's bytes counted and not parsed: round
    trips/s with no client work at all (against the echo: the target's denominator;
    against the simulator: the ceiling for any client of it)."""
    with socket.create_connection((host, port)) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        t0 = 0.0
        for i in range(100 + TCP_ROUND_TRIPS):
            if i == 100:
                t0 = time.perf_counter()
            sock.sendall(request)
            got = 0
            while got < reply_len:
                got += len(sock.recv(64))
        return TCP_ROUND_TRIPS / (time.perf_counter() - t0)


async def _client_breakdown(host: str, port: int, label: str) -> Breakdown:
    core = await connect_async(f"socket://{host}:{port}", transport="tcp",
                               query_interval_s=0.0, timeout=1.0)  # profiled: slower
    assert isinstance(core, Dyn232Axis)
    try:
        return await profile_async(label, core.drive_status)
    finally:
        await core.close()


async def _client_rate(host: str, port: int, transport: str) -> float:
    # a generous deadline: a reply late on a loaded host is counted in the rate, not fatal
    core = await connect_async(f"socket://{host}:{port}", transport=transport,
                               query_interval_s=0.0, timeout=1.0)
    assert isinstance(core, Dyn232Axis)
    # drive_status(): one READ_DRIVE_STATUS round trip (status() also reads the speed when
    # no profile runs, two round trips since issue 18, and the canned server answers
    # every request with a status reply)
    try:
        for _ in range(100):
            await core.drive_status()
        t0 = time.perf_counter()
        for _ in range(TCP_ROUND_TRIPS):
            await core.drive_status()
        return TCP_ROUND_TRIPS / (time.perf_counter() - t0)
    finally:
        await core.close()


class _FloorProtocol(asyncio.Protocol):
    """The least an asyncio client can do per round trip: write, wake on data_received."""

    def __init__(self) -> None:
        self.waiter: asyncio.Future[None] | None = None

    def data_received(self, data: bytes) -> None:
        if self.waiter is not None and not self.waiter.done():
            self.waiter.set_result(None)


async def _asyncio_floor_rate(host: str, port: int, request: bytes) -> float:
    """Round trips/s of a protocol-free asyncio client (one reply chunk per request): the
    ceiling for any asyncio client against the same server on this machine."""
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_connection(_FloorProtocol, host, port)
    transport.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    try:
        t0 = 0.0
        for i in range(100 + TCP_ROUND_TRIPS):
            if i == 100:
                t0 = time.perf_counter()
            protocol.waiter = loop.create_future()
            transport.write(request)
            await protocol.waiter
        return TCP_ROUND_TRIPS / (time.perf_counter() - t0)
    finally:
        transport.close()


def bench_tcp_round_trips() -> float:
    sim = [sys.executable, "-m", "servobus", "sim", "dyn232",
           "--fast", "--listen", "tcp://127.0.0.1:0", "--duration", "900"]
    echo = [sys.executable, "-c", _ECHO_SERVER, "900"]
    request = c.encode(0, DmmFunction.READ_DRIVE_STATUS, 0)
    reply_len = len(c.encode_reply(0, c.DriveFunction.IS_STATUS, 0))
    reply = c.encode_reply(0, c.DriveFunction.IS_STATUS, 0)
    canned = [sys.executable, "-c", _REPLY_SERVER, "900", reply.hex()]
    runs = loops()
    raw = floor = echo_floor = raw_sim = 0.0
    rates = dict.fromkeys((name for name, _ in runs), 0.0)
    # best of TCP_ROUNDS interleaved rounds per figure, as the other client benchmarks: a
    # single round put a passing burst of other work on one side of the ratio only
    with _server(echo) as (echo_host, echo_port), _server(sim) as (host, port):
        for _ in range(TCP_ROUNDS):
            raw = max(raw, _raw_echo_rate(echo_host, echo_port, request, reply_len))
            raw_sim = max(raw_sim, _raw_rate(host, port, request, reply_len))
            echo_floor = max(echo_floor, asyncio.run(
                _asyncio_floor_rate(echo_host, echo_port, request)))
            floor = max(floor, asyncio.run(_asyncio_floor_rate(host, port, request)))
            for name, factory in runs:
                rates[name] = max(rates[name], run_on(factory, _client_rate(host, port, "tcp")))
        via_pyserial = asyncio.run(_client_rate(host, port, "pyserial"))
        profiles = [run_on(factory, _client_breakdown(host, port, f"{name} drive_status()"))
                    for name, factory in runs]
    with _server(canned) as (host, port):
        client_only = asyncio.run(_client_rate(host, port, "tcp"))
    ours = rates["asyncio"]
    for name, rate in rates.items():
        share = rate / raw
        verdict = mark(f"dyn232 client: unpaced TCP round trips ({name})", share,
                       at_least=0.8, show=percent)
        print(f"unpaced status round trips over TCP, {name}: client + simulator "
              f"{rate:7.0f}/s vs raw socket echo {raw:7.0f}/s = {share:6.1%}  {verdict}")
    ratio = max(rates.values()) / raw
    print(f"  same client, pyserial socket:// {via_pyserial:7.0f}/s = {via_pyserial / raw:6.1%}; "
          f"same client vs a canned-reply server {client_only:7.0f}/s = {client_only / raw:6.1%} "
          f"(client cost alone)")
    print(f"  raw blocking client + simulator (no client work: the ceiling for any client) "
          f"{raw_sim:7.0f}/s = {raw_sim / raw:6.1%}; this client = {ours / raw_sim:6.1%} of it")
    print(f"  protocol-free asyncio client + simulator (ceiling for any asyncio client) "
          f"{floor:7.0f}/s = {floor / raw:6.1%}; this client = {ours / floor:6.1%} of it")
    print(f"  protocol-free asyncio client + the same echo server {echo_floor:7.0f}/s = "
          f"{echo_floor / raw:6.1%} (what asyncio alone leaves of the raw figure)")
    print_all(profiles)
    return ratio


def main() -> None:
    print("== DYN232M client (benchmarks/bench_dyn232_client.py)")
    for name, factory in loops():
        run_on(factory, bench_position_polls(name))
    print_all([run_on(factory, paced_breakdown(f"paced position() ({name})"))
               for name, factory in loops()])
    asyncio.run(bench_param_read())
    bench_tcp_round_trips()


if __name__ == "__main__":
    main()
    print(summary())
