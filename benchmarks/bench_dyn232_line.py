"""The virtual DYN232M line itself (no client library), measured against limits in the same run.

1. Paced position polls over TCP to ``servobus sim dyn232`` (own process) from a minimal raw
   socket host, vs the 38400-baud wire limit for the same bytes (target >= 97 %), and the
   server's CPU use while doing it (/proc, Linux).
2. The same through the in-process ``sim://dyn2`` stream.
3. Unpaced (``--fast``) round trips/s over TCP vs a raw socket echo server answering the same
   byte counts (both own processes, same client code).
4. ``Dyn232Line.receive`` alone: packets/s in stepped time (the protocol front end's cost).

Run: ``python -m benchmarks`` (all) or ``python -m benchmarks.bench_dyn232_line``.
"""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

from benchmarks.verdict import mark, percent, summary
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.device import Dyn232Line
from servobus.protocols.dyn232.inprocess import open_sim_stream
from servobus.sim.dmm.drive import VirtualDrive

SECONDS = 2.0
FAST_TRIPS = 3000
H, GR = c.HostFunction, c.GeneralReadSelector
CLI = [sys.executable, "-m", "servobus"]
ECHO = """
import asyncio, sys
async def handle(reader, writer):
    while data := await reader.read(4096):
        writer.write(data)
async def main():
    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    print("listening on tcp://127.0.0.1:%d" % server.sockets[0].getsockname()[1], flush=True)
    await asyncio.sleep(float(sys.argv[1]))
asyncio.run(main())
"""


@contextmanager
def server(args: list[str]) -> Iterator[tuple[int, int]]:
    """Start a server process; yield (pid, port)."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()
        if not line.startswith("listening on tcp://"):
            raise RuntimeError(f"server did not start: {line!r}")
        yield proc.pid, int(line.rsplit(":", 1)[1])
    finally:
        proc.terminate()
        proc.wait(10)


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process (Linux /proc)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def recv_exact(sock: socket.socket, n: int) -> bytes:
    got = b""
    while len(got) < n:
        chunk = sock.recv(64)
        if not chunk:
            raise ConnectionError("closed")
        got += chunk
    return got


def reply_len(request: bytes, port: int) -> int:
    with socket.create_connection(("127.0.0.1", port)) as sock:
        sock.sendall(request)
        sock.settimeout(0.5)
        time.sleep(0.05)
        return len(sock.recv(64))


def bench_paced_tcp() -> float:
    request = c.encode(0, DF.GENERAL_READ, GR.POSITION)
    with server([*CLI, "sim", "dyn232", "--duration", "60"]) as (pid, port):
        n_reply = reply_len(request, port)
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            cpu0, n, t0 = cpu_seconds(pid), 0, time.perf_counter()
            while time.perf_counter() - t0 < SECONDS:
                sock.sendall(request)
                recv_exact(sock, n_reply)
                n += 1
            elapsed = time.perf_counter() - t0
            cpu = (cpu_seconds(pid) - cpu0) / elapsed
    limit = c.BAUD / c.BITS_PER_BYTE / (len(request) + n_reply)
    ratio = n / elapsed / limit
    verdict = mark("dyn232 line: paced polls over TCP", ratio, at_least=0.97, show=percent)
    print(f"paced polls over TCP (raw host): {n / elapsed:6.1f}/s vs wire limit {limit:6.1f}/s "
          f"({len(request)}+{n_reply} bytes) = {ratio:6.1%} {verdict}; "
          f"server CPU {cpu:5.1%} of one core")
    return ratio


async def _inprocess() -> float:
    stream = open_sim_stream(ids=(0,), paced=True)
    request = c.encode(0, DF.GENERAL_READ, GR.POSITION)
    try:
        await stream.write(request)
        n_reply = len(await stream.read())
        n, t0, cpu0 = 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - t0 < SECONDS:
            await stream.write(request)
            got = 0
            while got < n_reply:
                got += len(await stream.read())
            n += 1
        elapsed = time.perf_counter() - t0
        cpu = (time.process_time() - cpu0) / elapsed
    finally:
        await stream.close()
    limit = c.BAUD / c.BITS_PER_BYTE / (len(request) + n_reply)
    ratio = n / elapsed / limit
    verdict = mark("dyn232 line: paced polls in-process", ratio, at_least=0.97, show=percent)
    print(f"paced polls in-process (raw host): {n / elapsed:6.1f}/s vs wire limit {limit:6.1f}/s "
          f"= {ratio:6.1%} {verdict}; process CPU (host + line) {cpu:5.1%}")
    return ratio


def _trips(port: int, request: bytes, n_reply: int) -> float:
    with socket.create_connection(("127.0.0.1", port)) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for _ in range(100):
            sock.sendall(request)
            recv_exact(sock, n_reply)
        t0 = time.perf_counter()
        for _ in range(FAST_TRIPS):
            sock.sendall(request)
            recv_exact(sock, n_reply)
        return FAST_TRIPS / (time.perf_counter() - t0)


def bench_fast_tcp() -> float:
    request = c.encode(0, DF.READ_DRIVE_STATUS)
    with server([*CLI, "sim", "dyn232", "--fast", "--duration", "60"]) as (_, port):
        ours = _trips(port, request, 4)
    with server([sys.executable, "-c", ECHO, "60"]) as (_, port):
        raw = _trips(port, request, 4)
    ratio = ours / raw
    print(f"unpaced round trips over TCP (raw host): sim {ours:7.0f}/s vs raw socket echo "
          f"{raw:7.0f}/s = {ratio:6.1%}")
    return ratio


def bench_line_receive() -> float:
    line = Dyn232Line([VirtualDrive(i) for i in (1, 2, 3)])
    packets = [c.encode(2, DF.GENERAL_READ, GR.POSITION), c.encode(1, DF.READ_DRIVE_STATUS),
               c.encode(3, H.READ_MAIN_GAIN), c.encode(9, DF.READ_DRIVE_ID)]
    blob = b"".join(packets) * 250
    t0, n = time.perf_counter(), 0
    while time.perf_counter() - t0 < 1.0:
        line.receive(blob)
        n += len(packets) * 250
    rate = n / (time.perf_counter() - t0)
    wire = c.BAUD / c.BITS_PER_BYTE / 4
    print(f"Dyn232Line.receive: {rate:8.0f} packets/s = {rate / wire:5.1f}x a saturated "
          f"38400-baud line of 4-byte packets")
    return rate


def main() -> None:
    print("== virtual DYN232M line (benchmarks/bench_dyn232_line.py)")
    bench_paced_tcp()
    asyncio.run(_inprocess())
    bench_fast_tcp()
    bench_line_receive()


if __name__ == "__main__":
    main()
    print(summary())
