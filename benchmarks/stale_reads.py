"""Stale reads under late replies: the DYN232M, DYN CAN, Modbus RTU and EasyCan clients
through a delaying link.

Profile (issue #8): 30 % of the drive's replies are delayed by a uniform 0..150 ms, order
kept (a delayed reply holds back the ones behind it, as on a wire). The drive answers each
position read with the number of requests it had received before it, so a value is older
than its call exactly when it is below that number at the start of the call.

``python -m benchmarks.stale_reads [READS]`` (default 885, the issue's run) prints, per
client and reception path, the stale count with the late-reply drain on (the default) and
off (``late_reply_s=0``, the behaviour before it). The tests reuse :func:`dyn232_stale`,
:func:`dyncan_stale`, :func:`modbus_stale` and :func:`easycan_stale` with fewer reads.
In-process, seeded, nothing listens anywhere. Modbus RTU (issue 17.7) runs at the YZ-AIM's
19200 baud with the client's own deadline (wire time + 50 ms turnaround), below the
profile's 150 ms delays, so timeouts and retries are in play as in the issue.
"""

from __future__ import annotations

import asyncio
import functools
import random
import sys
import time
from dataclasses import dataclass
from typing import Any

from servobus.errors import ServobusError
from servobus.families.yzaim import registers as Y
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.protocols.dyncan import codec as cc
from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import AsyncDynCanClient
from servobus.protocols.easycan import codec as ec
from servobus.protocols.easycan import messages as em
from servobus.protocols.easycan.axis import EasyCanAxis
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.modbus import codec as mc
from servobus.protocols.modbus.axis import ModbusAxis
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.transport.base import Direction
from servobus.transport.can_bus import CanFrame, FrameReceiver, FrameTraceHook
from servobus.transport.pair import Fault, Manipulator, PairStream, open_pair

DELAY_RATE = 0.3
MAX_DELAY_S = 0.15
SEED = 8
ISSUE_READS = 885
DRIVE_ID = 1


@dataclass(frozen=True)
class StaleCount:
    reads: int
    ok: int
    failed: int  # DriveTimeout after every attempt (the profile also loses deadlines)
    stale: int  # values older than the start of their call
    late: int  # replies recognised as owed by a timed-out attempt and dropped
    given_up: int
    seconds: float

    def line(self, label: str) -> str:
        return (f"{label:<38} {self.stale:4d} stale of {self.ok:4d} values "
                f"({self.failed} reads failed, {self.late} late replies dropped, "
                f"{self.given_up} given up) in {self.seconds:.1f} s")


class _Counter:
    """How many requests the drive has received (the value its next reply carries)."""

    def __init__(self) -> None:
        self.received = 0

    def next(self) -> int:
        value = self.received
        self.received += 1
        return value


async def _count_stale(read: Any, counter: _Counter, reads: int) -> tuple[int, int, int]:
    ok = failed = stale = 0
    for _ in range(reads):
        start = counter.received
        try:
            value = await read()
        except ServobusError:
            failed += 1
            continue
        ok += 1
        stale += value < start
    return ok, failed, stale


# ------------------------------------------------------------------ DYN232M over the pair
async def _serve_dyn232(device: PairStream, counter: _Counter) -> None:
    framer = c.Framer()
    try:
        while True:
            for packet in framer.feed(await device.read()):
                if isinstance(packet, c.Packet):
                    await device.write(c.encode_reply(packet.drive_id,
                                                      c.DriveFunction.IS_ABS_POS32,
                                                      counter.next()))
    except ConnectionError:
        pass


async def dyn232_stale(reads: int, *, push: bool = True, seed: int = SEED,
                       **client_kw: Any) -> StaleCount:
    faults = Manipulator(seed=seed, delay_s=0.0, delay_max_s=MAX_DELAY_S)
    faults.set_rate(Direction.RX, Fault.DELAY, DELAY_RATE)
    host, device = open_pair(faults, push=push)
    counter = _Counter()
    server = asyncio.create_task(_serve_dyn232(device, counter))
    client = AsyncDyn232Client(host, **client_kw)
    axis = Dyn232Axis(client, DRIVE_ID)
    t0 = time.monotonic()
    try:
        ok, failed, stale = await _count_stale(axis.position, counter, reads)
    finally:
        await client.close()
        await server
    late = client.late_replies
    return StaleCount(reads, ok, failed, stale, late.late, late.given_up,
                      time.monotonic() - t0)


# ------------------------------------------------------------------ DYN CAN, delaying port
def _dyncan_answer(arbitration_id: int, data: bytes, counter: _Counter
                   ) -> tuple[int, bytes] | None:
    request = cc.decode(arbitration_id, data)
    if not cc.expects_reply(request):
        return None
    answer = cc.reply(request.drive_id, cc.function_of(request.function), counter.next())
    return answer.arbitration_id, answer.data


def _easycan_answer(arbitration_id: int, data: bytes, counter: _Counter
                    ) -> tuple[int, bytes] | None:
    """Every register read answered with the counter (a 32-bit pair: low word first)."""
    request = ec.decode_request(arbitration_id, data)
    if not isinstance(request, em.ReadRequest):
        return None
    words = Y.split32(counter.next()) if request.count == 2 else (counter.next() & 0xFFFF,)
    return ec.encode(em.ReadReply(request.slave, request.address, words, request.host))


class DelayingCanPort:
    """A FramePort whose one drive answers every read with the counter, some late.

    Order is kept per bus: a delayed reply holds back the replies behind it.
    """

    def __init__(self, counter: _Counter, seed: int,
                 answer: Any = _dyncan_answer) -> None:
        self._answer = answer
        self._counter = counter
        self._rng = random.Random(seed)
        self._receiver: FrameReceiver | None = None
        self._release_at = 0.0
        self._closed = False

    def set_receiver(self, receiver: FrameReceiver) -> None:
        self._receiver = receiver

    def add_trace(self, hook: FrameTraceHook) -> None:
        pass

    async def send(self, arbitration_id: int, data: bytes) -> None:
        answer = self._answer(arbitration_id, bytes(data), self._counter)
        if answer is None:
            return
        delay = (self._rng.uniform(0.0, MAX_DELAY_S) if self._rng.random() < DELAY_RATE
                 else 0.0)
        loop = asyncio.get_running_loop()
        now = loop.time()
        if delay <= 0 and self._release_at <= now:
            self._deliver(answer)
            return
        self._release_at = max(self._release_at, now) + delay
        loop.call_at(self._release_at, self._deliver, answer)

    def _deliver(self, frame: tuple[int, bytes]) -> None:
        if self._receiver is not None and not self._closed:
            self._receiver(CanFrame(frame[0], frame[1]))

    async def recv(self, timeout: float | None = None) -> CanFrame | None:
        raise NotImplementedError("push only")

    async def close(self) -> None:
        self._closed = True
        if self._receiver is not None:
            self._receiver(None)


async def dyncan_stale(reads: int, *, seed: int = SEED, **client_kw: Any) -> StaleCount:
    counter = _Counter()
    client = AsyncDynCanClient(DelayingCanPort(counter, seed), **client_kw)
    axis = DynCanAxis(client, DRIVE_ID)
    t0 = time.monotonic()
    try:
        ok, failed, stale = await _count_stale(axis.position, counter, reads)
    finally:
        await client.close()
    late = client.late_replies
    return StaleCount(reads, ok, failed, stale, late.late, late.given_up,
                      time.monotonic() - t0)


# ------------------------------------------------------------------ EasyCan, delaying port
async def easycan_stale(reads: int, *, seed: int = SEED, **client_kw: Any) -> StaleCount:
    counter = _Counter()
    client = AsyncEasyCanClient(DelayingCanPort(counter, seed, _easycan_answer), **client_kw)
    axis = EasyCanAxis(client, DRIVE_ID)
    t0 = time.monotonic()
    try:
        ok, failed, stale = await _count_stale(axis.position, counter, reads)
    finally:
        await client.close()
    late = client.late_replies
    return StaleCount(reads, ok, failed, stale, late.late, late.given_up,
                      time.monotonic() - t0)


# ------------------------------------------------------------------ Modbus RTU over the pair
async def _serve_modbus(device: PairStream, counter: _Counter) -> None:
    """A device answering every read with the counter (32-bit pair, low word first)."""
    buf = bytearray()
    try:
        while True:
            buf += await device.read()
            while len(buf) >= mc.FIXED_FRAME_LENGTH:  # the client sends reads only
                request = mc.decode_request(bytes(buf[:mc.FIXED_FRAME_LENGTH]))
                del buf[:mc.FIXED_FRAME_LENGTH]
                assert isinstance(request, mc.ReadHoldingRequest)
                value = counter.next()
                words = (Y.split32(value) if request.count == 2
                         else tuple(value & 0xFFFF for _ in range(request.count)))
                await device.write(mc.encode_reply(mc.ReadHoldingReply(request.address,
                                                                       words)))
    except ConnectionError:
        pass


async def modbus_stale(reads: int, *, push: bool = True, seed: int = SEED,
                       **client_kw: Any) -> StaleCount:
    faults = Manipulator(seed=seed, delay_s=0.0, delay_max_s=MAX_DELAY_S)
    faults.set_rate(Direction.RX, Fault.DELAY, DELAY_RATE)
    host, device = open_pair(faults, push=push)
    counter = _Counter()
    server = asyncio.create_task(_serve_modbus(device, counter))
    client = AsyncModbusClient(host, **client_kw)
    axis = ModbusAxis(client, DRIVE_ID)
    t0 = time.monotonic()
    try:
        ok, failed, stale = await _count_stale(axis.position, counter, reads)
    finally:
        await client.close()
        await server
    late = client.late_replies
    return StaleCount(reads, ok, failed, stale, late.late, late.given_up,
                      time.monotonic() - t0)


async def _main(reads: int) -> None:
    print(f"== stale reads: {DELAY_RATE:.0%} of replies delayed 0..{MAX_DELAY_S * 1000:.0f} ms "
          f"(seed {SEED}), {reads} position reads each")
    runs: list[tuple[str, Any]] = [
        ("DYN232M push (TCP, sim://)", functools.partial(dyn232_stale, push=True)),
        ("DYN232M pull (pyserial)", functools.partial(dyn232_stale, push=False)),
        ("DYN CAN", dyncan_stale),
        ("Modbus RTU push (TCP, sim://)", functools.partial(modbus_stale, push=True)),
        ("Modbus RTU pull (pyserial)", functools.partial(modbus_stale, push=False)),
        ("EasyCan", easycan_stale),
    ]
    for label, run in runs:
        for drain, extra in (("off", {"late_reply_s": 0.0}), ("on", {})):
            count = await run(reads, **extra)
            print(count.line(f"{label}, drain {drain}"), flush=True)


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    asyncio.run(_main(int(args[0]) if args else ISSUE_READS))


if __name__ == "__main__":
    main()
