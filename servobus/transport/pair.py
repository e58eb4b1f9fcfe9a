"""In-process byte-stream pair with a fault-injecting manipulator (null modem).

Modelled on pymodbus' null-modem transport and its ``manipulator`` hook: the two ends of a
:func:`open_pair` behave like the two ends of a serial cable, and a :class:`Manipulator` sits
on the cable to drop, corrupt, delay, split or duplicate what one end writes, either as
scripted one-shot faults (``drop_next`` ...) or at seeded random rates. Tests use it to
prove the client's behaviour on a bad line without timing games.

Faults apply per ``write()`` call (clients write one packet per call). Delivery keeps the
order of a wire: a delayed chunk also holds back everything written after it.
"""

from __future__ import annotations

import asyncio
import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from servobus.errors import ArgumentRangeError, ConnectionLost
from servobus.transport.base import Direction
from servobus.transport.buffered import BufferedInput, PushInput


class Fault(Enum):
    DROP = "drop"  # the whole write vanishes
    CORRUPT = "corrupt"  # bit 0 of the last byte flips (framing kept, checksum broken)
    DELAY = "delay"  # delivered late
    SPLIT = "split"  # delivered in two chunks
    DUPLICATE = "duplicate"  # delivered twice


#: pymodbus-style custom manipulator: bytes written -> chunks to deliver (may be empty).
CustomHook = Callable[[Direction, bytes], list[bytes]]


@dataclass
class _Scripted:
    fault: Fault
    seconds: float = 0.0


@dataclass
class Manipulator:
    """Faults on the cable. Direction.TX = host end writes, Direction.RX = device end writes."""

    seed: int | None = None
    rates: dict[Direction, dict[Fault, float]] = field(default_factory=dict)
    delay_s: float = 0.005  # used by random DELAY and SPLIT gaps
    #: When set, a random DELAY lasts a uniform draw in [delay_s, delay_max_s] (jitter).
    delay_max_s: float | None = None
    custom: CustomHook | None = None
    counts: dict[Fault, int] = field(default_factory=lambda: dict.fromkeys(Fault, 0))

    def __post_init__(self) -> None:
        if self.delay_max_s is not None and not self.delay_s <= self.delay_max_s:
            raise ArgumentRangeError(
                f"delay_max_s={self.delay_max_s} must be >= delay_s={self.delay_s}")
        self._rng = random.Random(self.seed)
        self._script: dict[Direction, deque[_Scripted]] = {d: deque() for d in Direction}

    # ------------------------------------------------------------- scripted faults
    def _push(self, direction: Direction, fault: Fault, n: int, seconds: float = 0.0) -> None:
        for _ in range(n):
            self._script[direction].append(_Scripted(fault, seconds))

    def drop_next(self, n: int = 1, direction: Direction = Direction.RX) -> None:
        self._push(direction, Fault.DROP, n)

    def corrupt_next(self, n: int = 1, direction: Direction = Direction.RX) -> None:
        self._push(direction, Fault.CORRUPT, n)

    def delay_next(self, seconds: float, n: int = 1,
                   direction: Direction = Direction.RX) -> None:
        self._push(direction, Fault.DELAY, n, seconds)

    def split_next(self, n: int = 1, direction: Direction = Direction.RX,
                   gap_s: float = 0.0) -> None:
        self._push(direction, Fault.SPLIT, n, gap_s)

    def duplicate_next(self, n: int = 1, direction: Direction = Direction.RX) -> None:
        self._push(direction, Fault.DUPLICATE, n)

    def set_rate(self, direction: Direction, fault: Fault, probability: float) -> None:
        self.rates.setdefault(direction, {})[fault] = probability

    def clear(self) -> None:
        for q in self._script.values():
            q.clear()
        self.rates.clear()

    # ------------------------------------------------------------- application
    def apply(self, direction: Direction, data: bytes) -> list[tuple[float, bytes]]:
        """Chunks to deliver for one write, each with its extra delay in seconds."""
        if self.custom is not None:
            data_chunks = self.custom(direction, data)
            return [(0.0, chunk) for chunk in data_chunks]
        script = self._script[direction]
        if script:
            step = script.popleft()
            return self._do(step.fault, data, step.seconds)
        for fault, p in self.rates.get(direction, {}).items():
            if p > 0 and self._rng.random() < p:
                seconds = self.delay_s if fault in (Fault.DELAY, Fault.SPLIT) else 0.0
                if fault is Fault.DELAY and self.delay_max_s is not None:
                    seconds = self._rng.uniform(self.delay_s, self.delay_max_s)
                return self._do(fault, data, seconds)
        return [(0.0, data)]

    def _do(self, fault: Fault, data: bytes, seconds: float) -> list[tuple[float, bytes]]:
        self.counts[fault] += 1
        if fault is Fault.DROP or not data:
            return []
        if fault is Fault.CORRUPT:
            return [(0.0, data[:-1] + bytes((data[-1] ^ 0x01,)))]
        if fault is Fault.DELAY:
            return [(seconds, data)]
        if fault is Fault.SPLIT:
            cut = max(1, len(data) // 2)
            return [(0.0, data[:cut]), (seconds, data[cut:])]
        return [(0.0, data), (0.0, data)]  # DUPLICATE


class PairStream(BufferedInput):
    """One end of an in-process cable; implements :class:`ByteStream`, read with ``read()``.

    This class has no ``set_receiver``: it is a pull-only stream, as pyserial ports are.
    :class:`PushPairStream` (the default of :func:`open_pair`) adds push reception.
    """

    def __init__(self, is_host: bool, manipulator: Manipulator | None) -> None:
        super().__init__()
        self._is_host = is_host
        self._manipulator = manipulator
        self._peer: PairStream | None = None
        self._release_at = 0.0  # loop time before which nothing from this end is delivered
        self.bytes_written = 0
        self.bytes_received = 0

    @property
    def _out_direction(self) -> Direction:
        return Direction.TX if self._is_host else Direction.RX

    async def write(self, data: bytes) -> None:
        if self._closed:
            raise ConnectionLost("stream is closed")
        data = bytes(data)
        self.bytes_written += len(data)
        direction = self._out_direction
        self._trace(direction, data)
        peer = self._peer
        if peer is None or peer._closed:
            return  # like a cable with nobody at the far end
        chunks = ([(0.0, data)] if self._manipulator is None
                  else self._manipulator.apply(direction, data))
        loop = asyncio.get_running_loop()
        now = loop.time()
        for delay, chunk in chunks:
            if delay <= 0 and self._release_at <= now:
                peer._receive(chunk)
                continue
            self._release_at = max(self._release_at, now) + max(delay, 0.0)
            loop.call_at(self._release_at, peer._receive, chunk)

    def _receive(self, data: bytes) -> None:
        if self._closed:
            return
        self.bytes_received += len(data)
        self._received(data, Direction.RX if self._is_host else Direction.TX)

    async def close(self) -> None:
        if not self._mark_closed():
            return
        peer = self._peer
        if peer is not None:
            peer._mark_closed()  # hang-up is seen at both ends


class PushPairStream(PushInput, PairStream):
    """A :class:`PairStream` end that also pushes received chunks (``PushByteStream``)."""


def open_pair(manipulator: Manipulator | None = None, *,
              push: bool = True) -> tuple[PairStream, PairStream]:
    """(host end, device end) of a fresh in-process cable.

    ``push=False`` gives pull-only ends (no ``set_receiver``): a client reads them with
    ``read()``, the path pyserial streams take; the default ends offer both paths.
    """
    cls = PushPairStream if push else PairStream
    host, device = cls(True, manipulator), cls(False, manipulator)
    host._peer, device._peer = device, host
    return host, device
