"""Modbus RTU client speed against the wire limit at 19200 8N1, measured in the same run.

The wire limit of one read is its bytes (request 8 + reply 5 + 2 x registers, counted on
the stream) at 10 bits per byte, plus two t3.5 silences (Serial Line v1.02 2.5.1.1: the
device answers after the request's silence, and the host keeps one before its next
request): 1 register = 15 bytes + 2 x 1.823 ms = 11.46 ms, 87.3 reads/s.

1. Register reads/s through the paced in-process line (``sim://modbus``), one register and
   the 16-register status span, vs the wire limit for the same bytes and gaps. Target
   >= 95 % (what is lost: the host's wake-ups; its t3.5 wait ends by yielding to the loop,
   since an epoll loop's sleeps end only on the millisecond).
2. The same over TCP to ``servobus sim modbus`` (own process, paced). Target >= 95 %.
3. Unpaced (``fast=1``) round trips/s in-process: the client's own cost per transaction.

Run: ``python -m benchmarks modbus`` or ``python -m benchmarks.bench_modbus``.
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

from benchmarks.verdict import mark, percent, summary
from servobus.axis import connect_async
from servobus.protocols.modbus.axis import ModbusAxis
from servobus.protocols.modbus.timing import DEFAULT_BAUD, inter_frame_gap_s, wire_time_s
from servobus.transport.trace import ByteCounter

SECONDS = 3.0
FAST_READS = 5000
ALARM_CODE = 0x0E  # a one-register read
STATUS_SPAN = (0x01, 16)  # output_enable .. motor_speed: what status() reads


async def _reads_per_s(axis: ModbusAxis, start: int, count: int) -> tuple[float, float]:
    """(reads/s, bytes per read) over SECONDS."""
    counter = ByteCounter()
    axis.client.stream.add_trace(counter)
    await axis.read_words(start, count)
    tx0, rx0, n = counter.tx, counter.rx, 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < SECONDS:
        await axis.read_words(start, count)
        n += 1
    elapsed = time.perf_counter() - t0
    return n / elapsed, (counter.tx - tx0 + counter.rx - rx0) / n


def wire_limit(bytes_per_read: float, baud: int = DEFAULT_BAUD) -> float:
    """Reads/s the wire allows: the bytes plus two t3.5 silences per read."""
    return 1.0 / (wire_time_s(1, baud) * bytes_per_read + 2 * inter_frame_gap_s(baud))


def _report(what: str, rate: float, per_read: float, target: float | None) -> float:
    limit = wire_limit(per_read)
    ratio = rate / limit
    verdict = "" if target is None else mark(f"modbus: {what}", ratio, at_least=target,
                                             show=percent)
    print(f"{what}: {rate:6.1f}/s vs wire limit {limit:6.1f}/s ({per_read:.0f} bytes + 2 x "
          f"t3.5 per read) = {ratio:6.1%}  {verdict}")
    return ratio


async def bench_in_process() -> None:
    core = await connect_async("sim://modbus", drive_id=1)
    assert isinstance(core, ModbusAxis)
    try:
        rate, per_read = await _reads_per_s(core, ALARM_CODE, 1)
        _report("1-register reads, paced in-process line, 19200", rate, per_read, 0.95)
        rate, per_read = await _reads_per_s(core, *STATUS_SPAN)
        _report("16-register reads, paced in-process line, 19200", rate, per_read, 0.95)
    finally:
        await core.close()


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


async def bench_tcp(host: str, port: int) -> None:
    core = await connect_async(f"modbus+socket://{host}:{port}", drive_id=1)
    assert isinstance(core, ModbusAxis)
    try:
        rate, per_read = await _reads_per_s(core, ALARM_CODE, 1)
        _report("1-register reads over TCP to `sim modbus`, 19200", rate, per_read, 0.95)
    finally:
        await core.close()


async def bench_unpaced() -> None:
    core = await connect_async("sim://modbus?fast=1", drive_id=1)
    assert isinstance(core, ModbusAxis)
    try:
        for _ in range(100):
            await core.read_words(ALARM_CODE)
        t0 = time.perf_counter()
        for _ in range(FAST_READS):
            await core.read_words(ALARM_CODE)
        elapsed = time.perf_counter() - t0
    finally:
        await core.close()
    print(f"unpaced in-process round trips: {FAST_READS / elapsed:8.0f}/s "
          f"({elapsed / FAST_READS * 1e6:.1f} us per read, client + virtual line)")


def main() -> None:
    print("Modbus RTU (YZ-AIM), reads vs the wire limit at 19200 8N1:")
    asyncio.run(bench_in_process())
    args = [sys.executable, "-m", "servobus", "sim", "modbus", "--listen", "tcp://127.0.0.1:0",
            "--ids", "1", "--duration", "60"]
    with _server(args) as (host, port):
        asyncio.run(bench_tcp(host, port))
    asyncio.run(bench_unpaced())


if __name__ == "__main__":
    main()
    print(summary())
