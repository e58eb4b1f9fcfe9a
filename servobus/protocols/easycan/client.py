"""EasyCan host client over any python-can bus (the shared AsyncCanBus / FramePort).

One :class:`AsyncEasyCanClient` per bus serves any number of motors (EasyCanAxis per
motor, :class:`servobus.protocols.easycan.sync.SyncGroup` for several at once). The rules
every protocol shares (deadline from when the frame left, bounded read retries, writes
sent once, stats, trace, EEPROM guard, late replies, dead links) are the shared
:class:`~servobus.link.transaction.TransactionManager`'s: ``client.transactions`` is the
bus's manager (``stats``, ``late_replies`` and ``guard`` are its). What EasyCan adds
(servobus decisions, docs/easycan.md):

* Which commands may be re-sent is commands.py's rule (reads and setting writes; moves,
  saves, sync_control, the cache and the emergency stop are sent once, and their timeout
  says so); which reply answers which request, and which requests wait one at a time, is
  matching.py's (key = (motor, function), one lane per motor, one for replied cache writes).
* Per-attempt deadline ``timeout``, default 50 ms: a motor answers within a frame time
  (about 0.1 ms at 1 Mbit/s) plus its firmware's turn-around; the margin covers USB
  adapters, socketcand over TCP and a loaded host (the manual gives no timing).
* An error reply (function | 0x80) is the answer (never re-sent): DriveError naming the
  motor, the register and the drive's code; counted in ``stats.error_replies``. A 0x86 with
  code 0x05 answers a replied cache write (matching.py).
* A write reply that does not echo the written words raises DriveError: the motor did not
  apply it (servobus's virtual motor echoes what the register holds; see its module).
* The save flag (0x14 != 0) stores to EEPROM: it passes the EEPROM guard first (commands.py).
* Frames that answer nothing (another host's traffic, a late reply) are dropped and counted
  (``unmatched``, ``late_replies``; an undecodable frame in ``framing_errors``).
* A dead bus raises ConnectionLost in the reads that wait and in every call after.
"""

from __future__ import annotations

import logging
from typing import Any

from servobus import checks
from servobus.errors import (
    ArgumentRangeError,
    DriveError,
    DriveTimeout,
    FramingError,
)
from servobus.families.yzaim import registers as yzaim
from servobus.link.can import CanClient
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import DEFAULT_LATE_REPLY_S
from servobus.link.stats import TransactionStats
from servobus.link.transaction import DEFAULT_RETRIES, TransactionManager, check_call
from servobus.protocols.easycan import codec
from servobus.protocols.easycan.commands import EasyCanCommand
from servobus.protocols.easycan.describe import register_name
from servobus.protocols.easycan.functions import HOST_ADDRESS, Function, error_text
from servobus.protocols.easycan.matching import Key, describe_key, fits, reply_keys
from servobus.protocols.easycan.messages import (
    ErrorReply,
    PositionCacheWrite,
    PositionReply,
    ReadMultipleRequest,
    ReadReply,
    ReadRequest,
    Reply,
    Request,
    WriteReply,
    WriteRequest,
)
from servobus.transport.base import Direction
from servobus.transport.can_bus import AsyncCanBus, CanFrame, FramePort

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT_S = 0.05  # per attempt (module docstring)
DECODED_CACHE = 4096  # distinct reply frames remembered (then forgotten at once)
#: The counters of a bus (the one stats class of every protocol).
BusStats = TransactionStats


def check_options(timeout: object = None, retries: object = None,
                  late_reply_s: object = None, eeprom_guard: object = None) -> None:
    """The client's options as a user gives them (None: the default); ArgumentRangeError
    before anything is opened."""
    checks.optional_seconds("timeout", timeout)
    if retries is not None:
        checks.count("retries", retries)
    if late_reply_s is not None:
        checks.non_negative_seconds("late_reply_s", late_reply_s)
    if eeprom_guard is not None and not isinstance(eeprom_guard, EepromGuard):
        raise ArgumentRangeError(f"eeprom_guard must be an EepromGuard, got {eeprom_guard!r}")


def _own(command: object) -> EasyCanCommand:
    """An EasyCan command, or ArgumentRangeError (a request of another protocol)."""
    if not isinstance(command, EasyCanCommand):
        raise ArgumentRangeError(f"not an EasyCan command: {command!r}")
    return command


def _describe_request(command: EasyCanCommand) -> str:
    return f"motor {command.slave} to {command.what}"


def _trace_request(command: EasyCanCommand) -> object:
    return command.request


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


class AsyncEasyCanClient(CanClient[Key, EasyCanCommand, Reply]):
    """Executes EasyCanCommands on one CAN bus."""

    def __init__(self, port: FramePort, *, timeout: float | None = None,
                 retries: int | None = None, late_reply_s: float | None = None,
                 eeprom_guard: EepromGuard | None = None, host: int = HOST_ADDRESS) -> None:
        check_options(timeout, retries, late_reply_s, eeprom_guard)
        self.timeout = DEFAULT_TIMEOUT_S if timeout is None else timeout
        self.host = host
        #: The request last sent per key: while one waits it is the one of its key (lanes).
        self._sent: dict[Key, Request] = {}
        #: Decoded replies by data bytes (frozen, so shared): polling repeats the same frames.
        self._decoded: dict[bytes, Reply] = {}
        # the bus's transaction manager: one lane per motor, one for replied cache writes
        super().__init__(port, TransactionManager(
            self._write, link="CAN bus", describe_key=describe_key,
            describe_request=_describe_request, trace_request=_trace_request,
            retries=DEFAULT_RETRIES if retries is None else retries,
            late_reply_s=DEFAULT_LATE_REPLY_S if late_reply_s is None else late_reply_s,
            eeprom_guard=eeprom_guard), name="easycan-rx")

    # ------------------------------------------------------------- receiving
    def _on_can_frame(self, raw: CanFrame) -> None:
        tm = self.transactions
        if raw.is_extended_id or raw.arbitration_id != self.host:
            return  # requests (ours echoed by some adapters, another host's): not replies
        data = bytes(raw.data)
        reply = self._decoded.get(data)
        if reply is None:
            try:
                reply = codec.decode_reply(raw.arbitration_id, data)
            except FramingError as exc:
                tm.stray(exc)
                return
            if len(self._decoded) >= DECODED_CACHE:
                self._decoded.clear()
            self._decoded[data] = reply
        if tm.tracing:
            tm.trace(Direction.RX, reply)
        keys = reply_keys(reply)
        sent = self._sent
        for key in keys:
            request = sent.get(key)
            if request is not None and fits(request, reply) and tm.answer(key, reply):
                return
        if tm.late_replies:
            for key in keys:
                if tm.late(key):
                    return
        tm.stray(reply)

    # ------------------------------------------------------------- sending
    async def _write(self, command: EasyCanCommand) -> None:
        if command.expects_reply:  # its lane keeps any other request of its key waiting
            self._sent[command.key] = command.request
        await self.port.send(*command.frame)

    def check_alive(self) -> None:
        """ConnectionLost when the bus died or the client was closed."""
        self.transactions.check_alive()

    async def send_only(self, *commands: EasyCanCommand) -> None:
        """Commands without a reply (silent cache frames, position clear), back to back."""
        tm = self.transactions
        tm.check_alive()
        for command in commands:
            if _own(command).expects_reply:
                raise ArgumentRangeError(f"{command.what} has a reply: use execute()")
        for command in commands:
            await tm.send(command)

    async def execute(self, command: EasyCanCommand, *, retries: int | None = None,
                      timeout: float | None = None) -> Reply | None:
        """Send ``command``; its reply (checked), or None for a command without one."""
        tm = self.transactions
        tm.check_alive()
        if retries is not None or timeout is not None:
            check_call(retries, timeout)
        own = _own(command)
        if own.eeprom_item is not None:
            tm.check_eeprom(own.slave, own.eeprom_item)
        if not own.expects_reply:
            await tm.send(own)
            return None
        try:
            reply = await tm.request(own.key, own,
                                     deadline_s=self.timeout if timeout is None else timeout,
                                     retry_safe=own.retry_safe, retries=retries, lane=own.lane)
        except DriveTimeout as exc:
            if own.retry_safe:
                raise
            raise DriveTimeout(f"{exc}; it was sent once and is not re-sent") from None
        return self._check(own, reply)

    def _check(self, command: EasyCanCommand, reply: Reply) -> Reply:
        if isinstance(reply, ErrorReply):
            self.stats.error_replies += 1
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


async def open_easycan_client(can: str, *, timeout: float | None = None,
                              retries: int | None = None, late_reply_s: float | None = None,
                              eeprom_guard: EepromGuard | None = None,
                              **options: Any) -> AsyncEasyCanClient:
    """Open ``can`` ("INTERFACE:CHANNEL"); other keywords go to ``can.Bus``."""
    check_options(timeout, retries, late_reply_s, eeprom_guard)  # before the bus is opened
    port = await AsyncCanBus.open(can, **options)
    return AsyncEasyCanClient(port, timeout=timeout, retries=retries,
                              late_reply_s=late_reply_s, eeprom_guard=eeprom_guard)
