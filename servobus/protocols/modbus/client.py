"""Modbus RTU host client on any ByteStream (serial port, TCP bridge, ``sim://``, the pair).

One :class:`ModbusClient` per line (any number of devices on it). It moves register words;
what the registers mean is the device family's (:mod:`servobus.protocols.modbus.axis`).
The transaction rules are the :class:`~servobus.protocols.modbus.policy.RtuPolicy`'s
(deadlines, retries, gaps), in one place so that a shared transaction manager can replace
it; the rest is RTU's own:

* One transaction at a time per line (asyncio lock): RS-485 has one master, and RTU
  replies carry no transaction id - only the address, the function and (reads) the byte
  count (Modbus over Serial Line v1.02 2.4, 2.5.1).
* Stale input is dropped before each request (bytes buffered by the stream and by the reply
  framer), so a reply can only be taken from bytes that arrived after the request left.
  The :class:`~servobus.protocols.modbus.framer.ReplyFramer` takes only the normal reply or
  the exception reply of the one outstanding request and skips anything else (garbage,
  frames failing their CRC, replies of other shapes), so sync is never lost.
* Silence: no valid reply within the per-attempt deadline is a timeout; reads are re-sent
  up to ``retries`` times, writes never (a write may move the motor or start an action:
  sent exactly once, also when its reply is lost). When every attempt failed:
  DriveTimeout, or ChecksumError when the last attempt got a reply that failed its CRC.
* Late replies: a reply that comes after its deadline would answer the next request of the
  same address and function. Each timed-out attempt owes one; bytes that arrive between
  transactions are framed and pay those debts, and a request whose (address, function) is
  owed first waits until the debts are paid or ``late_reply_s`` passed quiet
  (:mod:`servobus.axis.late_replies`).
* Exception replies raise :class:`~servobus.errors.DriveError` naming the function, the
  register(s) and the exception code; they are answers (never re-sent).
* Broadcast (address 0): sent, nothing awaited (Serial Line 2.1).
* A dead link raises ConnectionLost at once, also in a call waiting for its reply, and in
  every call after.

Streams that push (TCP, ``sim://``, the pair) hand each chunk to :meth:`_on_data`; streams
that only ``read()`` (pyserial, the pull-only pair) get a reader task that does the same.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass

from servobus.axis import checks
from servobus.axis.base import AxisTraceHook
from servobus.axis.eeprom_guard import EepromGuard
from servobus.axis.late_replies import DEFAULT_LATE_REPLY_S, LateReplies
from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
)
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.framer import GapFramer, ReplyFramer
from servobus.protocols.modbus.policy import DEFAULT_RETRIES, DEFAULT_TURNAROUND_S, RtuPolicy
from servobus.protocols.modbus.sniff import REGISTER_NAMES, reply_event, request_event
from servobus.protocols.modbus.timing import DEFAULT_BAUD, wire_time_s
from servobus.transport.base import ByteStream, Direction, set_receiver

log = logging.getLogger(__name__)

#: What a late reply is matched on: (address, function) - all an RTU reply is sure to carry.
ReplyKey = tuple[int, int]


@dataclass
class LineStats:
    """Counters of one line (all devices on it)."""

    sent: int = 0
    replies: int = 0
    retries: int = 0
    timeouts: int = 0
    checksum_errors: int = 0  # reply candidates that failed their CRC
    exceptions: int = 0  # exception replies
    unmatched: int = 0  # frames with a good CRC that answered nothing waiting
    stray_bytes: int = 0  # bytes dropped between transactions


def key_of(request: C.Request) -> ReplyKey:
    return request.address, int(request.function)


def _describe_key(key: ReplyKey) -> str:
    return f"{C.function_name(key[1])} reply from address {key[0]}"


def registers_text(request: C.Request) -> str:
    """``0x0016 absolute_position_low`` or ``0x0016..0x0017 (absolute_position_low, ...)``."""
    if isinstance(request, C.WriteSingleRequest):
        start, count = request.register, 1
    else:
        start, count = request.start, request.count

    def name(address: int) -> str:
        return REGISTER_NAMES.get(address, "not a YZ-AIM register")

    if count == 1:
        return f"register 0x{start:04X} ({name(start)})"
    last = start + count - 1
    names = ", ".join(name(a) for a in range(start, min(last, start + 3) + 1))
    more = ", ..." if count > 4 else ""
    return f"registers 0x{start:04X}..0x{last:04X} ({names}{more})"


def exception_error(request: C.Request, reply: C.ExceptionReply) -> DriveError:
    why = C.EXCEPTION_TEXT.get(reply.code, "not a code the Modbus standard defines")
    return DriveError(
        f"drive {request.address} refused {C.function_name(request.function)} of "
        f"{registers_text(request)}: exception {reply.code} {reply.name} ({why})",
        code=reply.code, drive_id=request.address)


class ModbusClient:
    """Executes Modbus RTU transactions on one line (one ByteStream)."""

    def __init__(
        self,
        stream: ByteStream,
        *,
        baud: int = DEFAULT_BAUD,
        retries: int = DEFAULT_RETRIES,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        timeout: float | None = None,
        late_reply_s: float = DEFAULT_LATE_REPLY_S,
        eeprom_guard: EepromGuard | None = None,
    ) -> None:
        self.stream = stream
        self.policy = RtuPolicy(baud=baud, retries=retries, turnaround_s=turnaround_s,
                                timeout=timeout)
        self.late_replies: LateReplies[ReplyKey] = LateReplies(
            checks.non_negative_seconds("late_reply_s", late_reply_s), _describe_key)
        self.guard = eeprom_guard if eeprom_guard is not None else EepromGuard()
        self.stats = LineStats()
        self._framer = ReplyFramer()
        self._idle = GapFramer(self.policy.baud, eager=True)  # bytes between transactions
        self._lock = asyncio.Lock()
        self._hooks: list[AxisTraceHook] = []
        self._dead: ConnectionLost | None = None
        self._closed = False
        self._waiting: asyncio.Future[C.Reply] | None = None
        self._crc_mark = 0
        self._quiet_at = 0.0  # monotonic time from which our next frame may start
        self._reader: asyncio.Task[None] | None = None
        self._push = set_receiver(stream, self._on_data)

    @property
    def baud(self) -> int:
        return self.policy.baud

    # ------------------------------------------------------------- tracing
    def add_trace(self, hook: AxisTraceHook) -> None:
        """``hook(direction, item, t)``: every frame sent/received (decoded) and every error."""
        self._hooks.append(hook)

    def _trace(self, direction: Direction, item: object) -> None:
        t = time.monotonic()
        for hook in self._hooks:
            hook(direction, item, t)

    # ------------------------------------------------------------- public transactions
    async def read(self, address: int, start: int, count: int = 1, *,
                   retries: int | None = None, timeout: float | None = None) -> tuple[int, ...]:
        """Read ``count`` holding registers (function 0x03) from device ``address``."""
        request = C.ReadHoldingRequest(_device("read", address), start, count)
        reply = await self.transact(request, retries=retries, timeout=timeout)
        assert isinstance(reply, C.ReadHoldingReply)
        return reply.values

    async def write(self, address: int, start: int, values: Sequence[int], *,
                    timeout: float | None = None) -> C.Reply | None:
        """Write registers once: function 0x06 for one word, 0x10 for more (a 32-bit pair in
        one frame, so the device takes both words together). Address 0 broadcasts (None)."""
        words = tuple(values)
        request: C.Request
        if len(words) == 1:
            request = C.WriteSingleRequest(address, start, words[0])
        else:
            request = C.WriteMultipleRequest(address, start, words)
        return await self.transact(request, timeout=timeout)

    async def transact(self, request: C.Request, *, retries: int | None = None,
                       timeout: float | None = None) -> C.Reply | None:
        """Send ``request`` and return its reply (None for a broadcast). Reads are retried,
        writes sent exactly once (:class:`RtuPolicy`)."""
        if self._dead is not None:
            raise ConnectionLost(str(self._dead))
        raw = C.encode_request(request)  # ArgumentRangeError before anything is sent
        attempts = self.policy.attempts(request, retries)
        per_try = self.policy.deadline_s(request, timeout)
        async with self._lock:
            if self._dead is not None:
                raise ConnectionLost(str(self._dead))
            self._start_reader()
            if not C.expects_reply(request):
                await self._send(raw)
                return None
            return await self._transact(request, raw, attempts, per_try)

    # ------------------------------------------------------------- one transaction
    async def _transact(self, request: C.Request, raw: bytes, attempts: int,
                        per_try: float) -> C.Reply:
        key = key_of(request)
        late = self.late_replies
        if late and late.owed(key):
            await late.drain([key])
        last: DriveTimeout | ChecksumError | None = None
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
                log.debug("retry %d of %d: %s to drive %d after %s", attempt, attempts - 1,
                          C.function_name(request.function), request.address,
                          type(last).__name__)
            try:
                reply = await self._attempt(request, raw, per_try)
            except DriveTimeout as exc:
                late.owe(key)  # its reply may still come: never to a later call
                last = exc
                continue
            except ChecksumError as exc:
                last = exc
                continue
            if isinstance(reply, C.ExceptionReply):
                self.stats.exceptions += 1
                raise exception_error(request, reply)
            self.stats.replies += 1
            return reply
        assert last is not None
        if isinstance(last, DriveTimeout):
            raise DriveTimeout(
                f"no reply from drive {request.address} to {C.function_name(request.function)} "
                f"of {registers_text(request)} after {attempts} attempt(s) of "
                f"{per_try * 1000:.1f} ms" + ("" if isinstance(request, C.ReadHoldingRequest)
                                              else "; a write is sent once and not re-sent"))
        raise last

    async def _attempt(self, request: C.Request, raw: bytes, per_try: float) -> C.Reply:
        loop = asyncio.get_running_loop()
        await self._wait_quiet()
        self.stream.discard_input()
        framer = self._framer
        framer.expect(request)  # stale bytes are dropped here
        self._crc_mark = framer.crc_errors
        fut: asyncio.Future[C.Reply] = loop.create_future()
        self._waiting = fut
        timer = None
        try:
            await self._send(raw)
            if not fut.done():
                timer = loop.call_later(per_try, _expire, fut)
            return await fut
        except TimeoutError:
            raise self._timeout(request, per_try) from None
        finally:
            self._waiting = None
            if timer is not None:
                timer.cancel()

    async def _send(self, raw: bytes) -> None:
        if self._hooks:
            self._trace(Direction.TX, request_event(raw))
        self.stats.sent += 1
        try:
            await self.stream.write(raw)
        except OSError as exc:
            raise self._link_failed(exc) from exc
        # The frame occupies the line for its wire time, then t3.5 must pass (2.5.1.1).
        self._quiet_at = max(self._quiet_at, time.monotonic()) + wire_time_s(
            len(raw), self.policy.baud) + self.policy.gap_s

    async def _wait_quiet(self) -> None:
        """Keep t3.5 of silence before our next frame (after the last byte either way)."""
        wait = self._quiet_at - time.monotonic()
        if wait > 0:
            await asyncio.sleep(wait)

    def _timeout(self, request: C.Request, per_try: float) -> DriveTimeout:
        self.stats.timeouts += 1
        exc = DriveTimeout(f"no reply from drive {request.address} to "
                           f"{C.function_name(request.function)} within {per_try * 1000:.1f} ms")
        self._trace(Direction.RX, exc)
        log.debug("%s", exc)
        return exc

    # ------------------------------------------------------------- reception
    def _on_data(self, data: bytes | None) -> None:
        """Every received chunk (stream callback or reader task); None: the link died."""
        fut = self._waiting
        if data is None:
            lost = self._link_failed(ConnectionLost("stream closed"))
            if fut is not None and not fut.done():
                fut.set_exception(ConnectionLost(f"{lost} while waiting for a reply"))
            return
        now = time.monotonic()
        self._quiet_at = max(self._quiet_at, now + self.policy.gap_s)
        if fut is None or fut.done():
            self._between(data, now)
            return
        framer = self._framer
        reply = framer.feed(data)
        if reply is not None:
            if self._hooks:
                self._trace(Direction.RX, reply_event(C.encode_reply(reply)))
            fut.set_result(reply)
            return
        if framer.crc_errors != self._crc_mark and not framer.pending:
            self.stats.checksum_errors += framer.crc_errors - self._crc_mark
            exc = ChecksumError(f"a reply failed its CRC: {bytes(data).hex(' ')}", bytes(data))
            self._trace(Direction.RX, exc)
            fut.set_exception(exc)

    def _between(self, data: bytes, now: float) -> None:
        """Bytes while no request waits: owed late replies pay their debt; else dropped."""
        late = self.late_replies
        if not late:
            self.stats.stray_bytes += len(data)
            log.debug("dropped %d byte(s) received between transactions", len(data))
            return
        for frame in self._idle.feed(data, now):
            key = (frame.raw[0], frame.raw[1] & ~C.EXCEPTION_FLAG)
            if late.take(key):
                self._trace(Direction.RX, reply_event(frame.raw))
            else:
                self.stats.unmatched += 1

    def _start_reader(self) -> None:
        """Pull-only streams: one task reads and hands each chunk to :meth:`_on_data`."""
        if self._push or (self._reader is not None and not self._reader.done()):
            return
        self._reader = asyncio.get_running_loop().create_task(self._read_loop(),
                                                              name="modbus-rx")

    async def _read_loop(self) -> None:
        try:
            while True:
                self._on_data(await self.stream.read())
        except OSError:  # ConnectionLost and its kin: the link is gone
            self._on_data(None)

    def _link_failed(self, exc: BaseException) -> BaseException:
        out = checks.lost(exc, "Modbus link lost")
        if isinstance(out, ConnectionLost) and self._dead is None:
            self._dead = out
            self.late_replies.hang_up(ConnectionLost(str(out)))
            log.debug("link lost: %s", out)
        return out

    # ------------------------------------------------------------- lifetime
    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._dead is None:
            self._dead = ConnectionLost("client is closed")
        reader, self._reader = self._reader, None
        if reader is not None:
            reader.cancel()
        await self.stream.close()

    @property
    def closed(self) -> bool:
        return self._closed


def _device(what: str, address: int) -> int:
    if isinstance(address, bool) or not isinstance(address, int):
        raise ArgumentRangeError(f"device address must be an integer, got {address!r}")
    if address == C.BROADCAST:
        raise ArgumentRangeError(f"a {what} cannot be broadcast (address 0 gets no reply)")
    return address


def _expire(fut: asyncio.Future[C.Reply]) -> None:
    if not fut.done():
        fut.set_exception(TimeoutError())

