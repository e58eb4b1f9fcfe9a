"""Modbus RTU host client on any ByteStream (serial port, TCP bridge, ``sim://``, the pair).

One :class:`AsyncModbusClient` per line (any number of devices on it). It moves register words;
what the registers mean is the device family's (:mod:`servobus.protocols.modbus.axis`).
The transaction rules are the shared :class:`~servobus.link.transaction.TransactionManager`'s
(one lane: RS-485 has one master; deadlines measured from when the request left; reads
retried, writes sent exactly once; late replies; dead links; stats; trace); the timing is
the :class:`~servobus.protocols.modbus.policy.RtuPolicy`'s. What is RTU's own:

* Replies carry no transaction id - only the address, the function and (reads) the byte
  count (Modbus over Serial Line v1.02 2.4, 2.5.1). Stale input is dropped before each
  request (the stream's buffer and the reply framer's), so a reply can only be taken from
  bytes that arrived after the request left; the
  :class:`~servobus.protocols.modbus.framer.ReplyFramer` then takes only the normal reply
  or the exception reply of the one outstanding request and skips anything else (garbage,
  frames failing their CRC, replies of other shapes): sync is never lost.
* The key a late reply is matched on is (address, function). Bytes that arrive between
  transactions are framed by content and pay the debts of timed-out attempts.
* A reply candidate of the expected shape that fails its CRC fails the attempt at once
  (ChecksumError: a read is retried); silence fails it at its deadline (DriveTimeout).
* Exception replies raise :class:`~servobus.errors.DriveError` naming the function, the
  register(s) and the exception code; they are answers (never re-sent).
* The host keeps t3.5 of silence before each frame (Serial Line 2.5.1.1), after the last
  byte it received, or the wire time of its last frame when nothing came back.
* Broadcast (address 0): written once, nothing awaited (Serial Line 2.1).

Streams that push (TCP, ``sim://``, the pair) hand each chunk to :meth:`_on_data`; streams
that only ``read()`` (pyserial, the pull-only pair) are read by the manager through
``pull`` whenever a reply or a late reply is due.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from servobus import checks
from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    DriveError,
    DriveTimeout,
)
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import DEFAULT_LATE_REPLY_S
from servobus.link.stream import StreamClient
from servobus.link.transaction import DEFAULT_RETRIES, check_call
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus import commands
from servobus.protocols.modbus.framer import GapFramer, ReplyFramer
from servobus.protocols.modbus.policy import DEFAULT_TURNAROUND_S, RtuPolicy
from servobus.protocols.modbus.sniff import REGISTER_NAMES, reply_event, request_event
from servobus.protocols.modbus.timing import DEFAULT_BAUD, wire_time_s
from servobus.transport.base import ByteStream, Direction

log = logging.getLogger(__name__)

GAP_YIELD_S = 0.001  # the end of the frame gap is waited by yielding (see _keep_gap)
#: What a reply is matched on: (address, function) - all an RTU reply is sure to carry.
ReplyKey = tuple[int, int]


@dataclass(frozen=True)
class Outgoing:
    """One request as the line takes it: the decoded request and its frame."""

    request: C.Request
    raw: bytes

    @property
    def key(self) -> ReplyKey:
        return key_of(self.request)


def key_of(request: C.Request) -> ReplyKey:
    return request.address, int(request.function)


def _describe_key(key: ReplyKey) -> str:
    return f"{C.function_name(key[1])} reply from drive {key[0]}"


def registers_text(request: C.Request) -> str:
    """``register 0x0016 (absolute_position_low)`` or ``registers 0x0016..0x0017 (...)``."""
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


def _describe_request(out: Outgoing) -> str:
    request = out.request
    return (f"drive {request.address} to {C.function_name(request.function)} of "
            f"{registers_text(request)}")


def exception_error(request: C.Request, reply: C.ExceptionReply) -> DriveError:
    why = C.EXCEPTION_TEXT.get(reply.code, "not a code the Modbus standard defines")
    return DriveError(
        f"drive {request.address} refused {C.function_name(request.function)} of "
        f"{registers_text(request)}: exception {reply.code} {reply.name} ({why})",
        code=reply.code, drive_id=request.address)


class AsyncModbusClient(StreamClient[ReplyKey, Outgoing, C.Reply]):
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
        frame_gap_s: float | None = None,
    ) -> None:
        self.policy = RtuPolicy(baud=baud, turnaround_s=turnaround_s, timeout=timeout,
                                frame_gap_s=frame_gap_s)
        self._framer = ReplyFramer()
        self._idle = GapFramer(self.policy.baud, eager=True)  # bytes between transactions
        self._armed: ReplyKey | None = None  # the key of the request the framer answers
        self._crc_mark = 0
        self._quiet_at = 0.0  # monotonic time from which our next frame may start
        # The line's transaction manager: one lane, one transaction at a time.
        super().__init__(stream, self._write, link="Modbus RTU link",
                         describe_key=_describe_key, describe_request=_describe_request,
                         trace_request=_trace_request, retries=retries,
                         late_reply_s=late_reply_s, eeprom_guard=eeprom_guard)

    @property
    def baud(self) -> int:
        return self.policy.baud

    @staticmethod
    def check_options(options: Mapping[str, object]) -> None:
        """Check constructor keywords before anything is opened (ArgumentRangeError)."""
        checkers: dict[str, Callable[[str, object], object]] = {
            "baud": checks.positive_int, "retries": checks.count,
            "turnaround_s": checks.non_negative_seconds,
            "timeout": checks.optional_seconds, "late_reply_s": checks.non_negative_seconds,
            "frame_gap_s": checks.non_negative_seconds,
        }
        for name, value in options.items():
            if name == "eeprom_guard":
                if value is not None and not isinstance(value, EepromGuard):
                    raise ArgumentRangeError(f"eeprom_guard must be an EepromGuard, got "
                                             f"{value!r}")
                continue
            check = checkers.get(name)
            if check is None:
                raise ArgumentRangeError(f"unknown Modbus client option {name!r}")
            check(name, value)

    # ------------------------------------------------------------- public transactions
    async def read(self, address: int, start: int, count: int = 1, *,
                   retries: int | None = None, timeout: float | None = None) -> tuple[int, ...]:
        """Read ``count`` holding registers (function 0x03) from device ``address``."""
        reply = await self.transact(commands.make_read(address, start, count),
                                    retries=retries, timeout=timeout)
        assert isinstance(reply, C.ReadHoldingReply)
        return reply.values

    async def write(self, address: int, start: int, values: Sequence[int], *,
                    timeout: float | None = None) -> C.Reply | None:
        """Write registers once: function 0x06 for one word, 0x10 for more (a 32-bit pair in
        one frame, so the device takes both words together). Address 0 broadcasts (None)."""
        return await self.transact(commands.make_write(address, start, values),
                                   timeout=timeout)

    async def transact(self, request: C.Request, *, retries: int | None = None,
                       timeout: float | None = None) -> C.Reply | None:
        """Send ``request`` and return its reply (None for a broadcast). Reads are retried,
        writes sent exactly once. An exception reply raises DriveError."""
        tm = self.transactions
        tm.check_alive()
        check_call(retries, timeout)
        out = Outgoing(request, C.encode_request(request))  # ArgumentRangeError: nothing sent
        if not C.expects_reply(request):
            async with tm.lane():
                await tm.send(out)
            return None
        is_read = isinstance(request, C.ReadHoldingRequest)
        try:
            reply = await tm.request(out.key, out, deadline_s=self.policy.deadline_s(
                request, timeout), retry_safe=is_read, retries=retries)
        except DriveTimeout as exc:
            if is_read:
                raise
            raise DriveTimeout(f"{exc}; a write is sent once and not re-sent: the motor may "
                               "have taken it") from None
        if isinstance(reply, C.ExceptionReply):
            tm.stats.error_replies += 1
            raise exception_error(request, reply)
        return reply

    # ------------------------------------------------------------- the medium
    async def _write(self, out: Outgoing) -> None:
        """Hand one frame to the line after t3.5 of silence; arm the reply framer first."""
        await self._keep_gap()
        if C.expects_reply(out.request):
            self._framer.expect(out.request)  # bytes still buffered are dropped here
            self._armed = out.key
            self._crc_mark = self._framer.crc_errors
        # The frame occupies the line for its wire time, then t3.5 must pass (2.5.1.1);
        # a reply (even one that comes during the write, in-process) moves this on.
        self._quiet_at = time.monotonic() + wire_time_s(
            len(out.raw), self.policy.baud) + self.policy.gap_s
        await self.stream.write(out.raw)

    async def _keep_gap(self) -> None:
        """Wait until the line has been quiet for the frame gap. An epoll loop wakes only to
        the millisecond (a 1.8 ms sleep lasts 2+ ms, 2 % of a one-register read), so the
        last ``GAP_YIELD_S`` are waited by yielding to the loop: other tasks still run."""
        while True:
            wait = self._quiet_at - time.monotonic()
            if wait <= 0:
                return
            await asyncio.sleep(wait - GAP_YIELD_S if wait > GAP_YIELD_S else 0)

    def _reset_receiver(self) -> None:
        self._armed = None

    # ------------------------------------------------------------- reception
    def _on_bytes(self, data: bytes) -> None:
        """Every received chunk (push callback or ``pull``)."""
        tm = self.transactions
        now = time.monotonic()
        # Bytes from the line: the line is busy until now (a reply also proves that our
        # request has left), quiet t3.5 after.
        self._quiet_at = now + self.policy.gap_s
        key = self._armed
        if key is None or not tm.awaiting_reply:
            self._between(data, now)
            return
        framer = self._framer
        reply = framer.feed(data)
        if reply is not None:
            self._armed = None
            if tm.answer(key, reply) and tm.tracing:
                tm.trace(Direction.RX, reply_event(C.encode_reply(reply)))
            return
        if framer.crc_errors != self._crc_mark and not framer.pending:
            self._crc_mark = framer.crc_errors
            exc = ChecksumError(f"a reply failed its CRC: {bytes(data).hex(' ')}", bytes(data))
            tm.trace(Direction.RX, exc)
            tm.stray(exc)
            tm.reject(exc)  # the attempt fails now; a read is retried

    def _between(self, data: bytes, now: float) -> None:
        """Bytes while no request waits: owed late replies pay their debt; else strays."""
        tm = self.transactions
        if not tm.late_replies:
            log.debug("dropped %d byte(s) received between transactions", len(data))
            return
        for frame in self._idle.feed(data, now):
            key = (frame.raw[0], frame.raw[1] & ~C.EXCEPTION_FLAG)
            event = reply_event(frame.raw)
            if tm.late(key):
                if tm.tracing:
                    tm.trace(Direction.RX, event)
            else:
                tm.stray(event)



def _trace_request(out: Outgoing) -> object:
    return request_event(out.raw)
