"""EasyCan host client over any python-can bus (the shared AsyncCanBus / FramePort).

One :class:`AsyncEasyCanClient` per bus serves any number of motors (EasyCanAxis per
motor, :class:`servobus.protocols.easycan.sync.SyncStream` for several at once). The retry
and deadline rules are :class:`servobus.protocols.easycan.policy.TransactionPolicy`'s.

Matching (servobus decisions, docs/easycan.md):

* Replies travel on the host's identifier 0xFF and name the answering motor (5.3), except
  the position-cache reply, which is the bare position. A reply answers the waiting request
  of its motor when the codec says it fits (function, register, count); transactions to one
  motor run one at a time, different motors concurrently.
* Position-cache writes with reply (0x300|address) run one at a time on the whole bus, and
  the client reads single registers with 0x03, never a one-register 0x12: then a 4-byte
  frame on 0xFF is always a position reply (the codec's ambiguity never arises).
* An error reply (function | 0x80) fails the waiting request of that motor with DriveError
  naming the motor, the register and the drive's code; a 0x86 (code 0x05) answers a
  position-cache write with reply (the codec's decision).
* A write reply that does not echo the written words raises DriveError: the motor did not
  apply it (servobus's virtual motor echoes what the register holds; see its module).
* Frames that answer nothing (another host's traffic, a late reply) are dropped and counted.
* A dead bus raises ConnectionLost in the reads that wait and in every call after.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass, field
from typing import Any

from servobus.axis import checks
from servobus.axis.base import AxisTraceHook
from servobus.axis.late_replies import LateReplies
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
    FramingError,
)
from servobus.families import yzaim
from servobus.protocols.easycan import codec
from servobus.protocols.easycan.commands import EasyCanCommand
from servobus.protocols.easycan.describe import register_name
from servobus.protocols.easycan.functions import (
    CACHE_ERROR_FUNCTION,
    HOST_ADDRESS,
    Function,
    error_text,
)
from servobus.protocols.easycan.messages import (
    ErrorReply,
    PositionCacheWrite,
    PositionReply,
    ReadMultipleRequest,
    ReadReply,
    ReadRequest,
    Reply,
    WriteReply,
    WriteRequest,
)
from servobus.protocols.easycan.policy import TransactionPolicy
from servobus.transport.base import Direction
from servobus.transport.can_bus import AsyncCanBus, CanFrame, FramePort, set_receiver

log = logging.getLogger(__name__)

DECODED_CACHE = 4096  # distinct reply frames remembered (then forgotten at once)
POSITION_KEY = (-1, 0x300)  # late-reply key of position-cache replies (no motor address)
Key = tuple[int, int]


@dataclass
class ClientStats:
    sent: int = 0
    replies: int = 0
    retries: int = 0
    timeouts: int = 0
    drive_errors: int = 0
    unmatched: int = 0


@dataclass
class _Waiter:
    command: EasyCanCommand
    future: asyncio.Future[Reply] = field(repr=False)


def _expire(future: asyncio.Future[Reply]) -> None:
    if not future.done():
        future.set_exception(TimeoutError())


def reply_key(command: EasyCanCommand) -> Key:
    request = command.request
    if isinstance(request, PositionCacheWrite):
        return POSITION_KEY
    return request.slave, int(request.function)


def _describe_key(key: Key) -> str:
    if key == POSITION_KEY:
        return "position-cache reply"
    return f"{Function(key[1]).name} reply from motor {key[0]}"


def _fits(request: Any, reply: Reply) -> bool:
    if isinstance(request, PositionCacheWrite) and isinstance(reply, ErrorReply):
        return reply.slave == request.slave and reply.function == CACHE_ERROR_FUNCTION
    return codec.answers(request, reply)


def _name(address: int) -> str:
    return register_name(address) if address in yzaim.BY_ADDRESS else "no register"


def _what_register(command: EasyCanCommand) -> str:
    request = command.request
    if isinstance(request, ReadRequest | WriteRequest):
        pair = yzaim.PAIR_BY_LOW.get(request.address)
        span = len(request.values) if isinstance(request, WriteRequest) else request.count
        name = pair.name if pair is not None and span == 2 else _name(request.address)
        return f"{name} (0x{request.address:02X})"
    if isinstance(request, ReadMultipleRequest):
        return ", ".join(f"{_name(a)} (0x{a:02X})" for a in request.addresses)
    if isinstance(request, PositionCacheWrite):
        return "position_cache (0x1A)"
    return Function(request.function).name


class AsyncEasyCanClient:
    """Executes EasyCanCommands on one CAN bus."""

    def __init__(self, port: FramePort, *, policy: TransactionPolicy | None = None,
                 host: int = HOST_ADDRESS) -> None:
        self.policy = policy if policy is not None else TransactionPolicy()
        self.port = port
        self.host = host
        self.stats = ClientStats()
        #: Replies owed by timed-out attempts (``late_replies.late``, ``.given_up``).
        self.late_replies: LateReplies[Key] = LateReplies(self.policy.late_reply_s,
                                                          _describe_key)
        self._hooks: list[AxisTraceHook] = []
        #: Decoded replies by data bytes (frozen, so shared): polling repeats the same frames.
        self._decoded: dict[bytes, Reply] = {}
        self._waiters: list[_Waiter] = []
        self._locks: dict[int, asyncio.Lock] = {}
        self._position_lock = asyncio.Lock()
        self._closed = False
        self._dead: ConnectionLost | None = None
        self._rx_task: asyncio.Task[None] | None = None
        if not set_receiver(port, self._on_frame):
            self._rx_task = asyncio.get_running_loop().create_task(self._receive_loop(),
                                                                   name="easycan-rx")

    # ------------------------------------------------------------- tracing
    def add_trace(self, hook: AxisTraceHook) -> None:
        """``hook(direction, item, t)``: every message sent/received and every error met."""
        self._hooks.append(hook)

    def _trace(self, direction: Direction, item: object) -> None:
        t = time.monotonic()
        for hook in self._hooks:
            hook(direction, item, t)

    # ------------------------------------------------------------- receiving
    async def _receive_loop(self) -> None:
        while True:
            try:
                raw = await self.port.recv(None)
            except OSError as exc:
                self._bus_failed(exc)
                self._on_frame(None)
                return
            if raw is not None:
                self._on_frame(raw)

    def _on_frame(self, raw: CanFrame | None) -> None:
        if raw is None:
            dead = self._bus_failed(ConnectionLost("CAN bus closed"))
            for w in self._waiters:
                if not w.future.done():
                    w.future.set_exception(ConnectionLost(
                        f"{dead} while motor {w.command.slave} was to answer "
                        f"{w.command.what}"))
            return
        if raw.is_extended_id or raw.arbitration_id != self.host:
            return  # requests (ours echoed by some adapters, another host's): not replies
        data = bytes(raw.data)
        reply = self._decoded.get(data)
        if reply is None:
            try:
                reply = codec.decode_reply(raw.arbitration_id, data)
            except FramingError as exc:
                self.stats.unmatched += 1
                log.debug("undecodable frame on 0x%03X: %s", raw.arbitration_id, exc)
                return
            if len(self._decoded) >= DECODED_CACHE:
                self._decoded.clear()
            self._decoded[data] = reply
        if self._hooks:
            self._trace(Direction.RX, reply)
        for w in self._waiters:
            if not w.future.done() and _fits(w.command.request, reply):
                w.future.set_result(reply)
                return
        late = self.late_replies
        key = POSITION_KEY if isinstance(reply, PositionReply) else (reply.slave,
                                                                    reply.function)
        if late and late.take(key):
            return
        self.stats.unmatched += 1
        log.debug("unmatched reply %s", reply)

    # ------------------------------------------------------------- sending
    async def _send(self, command: EasyCanCommand) -> None:
        if self._hooks:
            self._trace(Direction.TX, command.request)
        self.stats.sent += 1
        try:
            await self.port.send(*codec.encode(command.request))
        except OSError as exc:
            raise self._bus_failed(exc) from exc

    def _bus_failed(self, exc: BaseException) -> BaseException:
        out = checks.lost(exc, "CAN bus lost")
        if isinstance(out, ConnectionLost) and self._dead is None:
            self._dead = out
            self.late_replies.hang_up(ConnectionLost(str(out)))
        return out

    def check_alive(self) -> None:
        if self._dead is not None:
            raise ConnectionLost(str(self._dead))

    async def send_only(self, *commands: EasyCanCommand) -> None:
        """Commands without a reply (silent cache frames, position clear), back to back."""
        self.check_alive()
        for command in commands:
            if codec.expects_reply(command.request):
                raise ArgumentRangeError(f"{command.what} has a reply: use execute()")
        for command in commands:
            await self._send(command)

    async def execute(self, command: EasyCanCommand, *, retries: int | None = None,
                      timeout: float | None = None) -> Reply | None:
        """Send ``command``; its reply (checked), or None for a command without one."""
        self.check_alive()
        attempts = self.policy.attempts(command.retry_safe, retries)
        deadline = self.policy.deadline(timeout)
        if not codec.expects_reply(command.request):
            await self._send(command)
            return None
        if isinstance(command.request, PositionCacheWrite):
            lock = self._position_lock
        else:
            lock = self._locks.setdefault(command.slave, asyncio.Lock())
        async with lock:
            reply = await self._transact(command, attempts, deadline)
        return self._check(command, reply)

    async def _transact(self, command: EasyCanCommand, attempts: int,
                        deadline: float) -> Reply:
        loop = asyncio.get_running_loop()
        key = reply_key(command)
        late = self.late_replies
        if late:
            await late.drain([key])
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
                log.debug("retry %d of %d: %s to motor %d", attempt, attempts - 1,
                          command.what, command.slave)
            waiter = _Waiter(command, loop.create_future())
            self._waiters.append(waiter)
            timer = loop.call_later(deadline, _expire, waiter.future)
            try:
                await self._send(command)
                reply = await waiter.future
            except TimeoutError:
                self.stats.timeouts += 1
                late.owe(key)
                if self._hooks:
                    self._trace(Direction.RX, DriveTimeout(
                        f"no reply from motor {command.slave} to {command.what}"))
                continue
            finally:
                timer.cancel()
                self._waiters.remove(waiter)
            self.stats.replies += 1
            return reply
        once = "" if command.retry_safe else "; it was sent once and is not re-sent"
        raise DriveTimeout(
            f"no reply from motor {command.slave} to {command.what} after {attempts} "
            f"attempt(s) of {deadline * 1000:.1f} ms{once}")

    def _check(self, command: EasyCanCommand, reply: Reply) -> Reply:
        if isinstance(reply, ErrorReply):
            self.stats.drive_errors += 1
            raise DriveError(
                f"motor {reply.slave} refused {command.what} [{_what_register(command)}]: "
                f"error 0x{reply.code:02X} {error_text(reply.code)}",
                code=reply.code, drive_id=reply.slave)
        if (command.echo is not None and isinstance(reply, WriteReply)
                and reply.values != command.echo):
            shown = "/".join(str(v) for v in reply.values)
            raise DriveError(
                f"motor {reply.slave} did not apply {command.what} "
                f"[{_what_register(command)}]: it holds {shown} (read-only, out of range, or "
                "modbus_enable 0)", drive_id=reply.slave)
        return reply

    # ------------------------------------------------------------- typed helpers
    async def read(self, command: EasyCanCommand, **kw: Any) -> int:
        """A ``make_read`` command's value, decoded with the family table."""
        reply = await self.execute(command, **kw)
        if not isinstance(reply, ReadReply) or command.name is None:
            raise FramingError(f"{command.what}: unexpected reply {reply!r}")
        return yzaim.decode_parameter(command.name, reply.values)

    async def read_words(self, command: EasyCanCommand, **kw: Any) -> tuple[int, ...]:
        reply = await self.execute(command, **kw)
        values = getattr(reply, "values", None)
        if not isinstance(values, tuple):
            raise FramingError(f"{command.what}: unexpected reply {reply!r}")
        return values

    async def position_write(self, command: EasyCanCommand) -> int | None:
        """A move or cache write with reply: the current absolute position it returns."""
        reply = await self.execute(command)
        if isinstance(reply, PositionReply):
            return reply.position
        if isinstance(reply, WriteReply):
            return reply.position
        return None

    # ------------------------------------------------------------- closing
    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._dead is None:
            self._dead = ConnectionLost("client is closed")
        await self.port.close()
        if self._rx_task is not None:
            self._rx_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._rx_task

    @property
    def closed(self) -> bool:
        return self._closed


async def open_easycan_client(can: str, *, timeout: float | None = None,
                              retries: int | None = None, late_reply_s: float | None = None,
                              **options: Any) -> AsyncEasyCanClient:
    """Open ``can`` ("INTERFACE:CHANNEL"); other keywords go to ``can.Bus``."""
    kw: dict[str, object] = {"timeout": timeout}
    if retries is not None:
        kw["retries"] = retries
    if late_reply_s is not None:
        kw["late_reply_s"] = late_reply_s
    policy = TransactionPolicy.checked(**kw)  # before the bus is opened
    port = await AsyncCanBus.open(can, **options)
    return AsyncEasyCanClient(port, policy=policy)

