"""DYN232M host client: executes pure ``make_*`` Commands over any ByteStream.

Transaction rules (the manual gives none; these are servobus decisions):

* The rules every protocol shares (deadline, retries, pacing, stats, trace, EEPROM guard,
  late replies, dead links) are :mod:`servobus.link.transaction`'s; ``client.transactions``
  is the line's manager (``stats``, ``late_replies`` and ``guard`` are its), owned as on
  every byte-stream client by :class:`servobus.link.stream.StreamClient`. What follows
  is how DYN232M applies them.
* One transaction at a time per line (one lane): RS485 has one master and replies carry
  no sequence number; a command without a reply also waits for a transaction in progress.
* A reply matches when its drive id AND its ``Is_*`` function match the request. Anything
  else is traced, counted in ``stats.unmatched`` and dropped; the framer keeps sync across
  garbage and truncated packets. The host's own echo on a 2-wire RS485 adapter never
  matches (no host function code equals the reply code it asks for).
* Reply deadline per attempt = wire time of request + longest reply (7 bytes) at the baud
  rate + ``turnaround_s`` (default 25 ms: the drive answers in well under 1 ms, the margin
  covers OS scheduling and USB-serial latency timers, 16 ms on FTDI by default).
  ``timeout=`` overrides the whole per-attempt deadline.
* Only reads (``Command.retry_safe``) are re-sent, at most ``retries`` times (default 2),
  after discarding pending input. Motion, settings and actions are written exactly once and
  never wait for anything (the drive sends nothing back for them).
* A reply that fails its checksum is counted in ``stats.checksum_errors`` and traced, never
  parsed; it fails the attempt that waits (its id cannot be trusted) and the read is
  retried. When every attempt failed, the last failure is raised:
  ChecksumError if the last reply was corrupt, otherwise DriveTimeout.
* Query pacing: ``query_interval_s`` is the minimum time from when one query's bytes have
  left (the stream's ``write`` returned) to the next query (commands with a reply).
  docs/dyn232.md: real drives may drop queries above ~50/s, so 0.02 is the safe value on
  hardware; the default 0 is for simulators and fast links. A dropped query is still
  detected (deadline) and retried.
* EEPROM settings (parameters, config, id) pass the EepromGuard before a byte is sent.
* Late replies: a reply to a read that timed out can still come and would match the next
  read of the same kind (id and function are all a reply carries). Each timed-out attempt
  owes a reply; an owed reply that arrives outside its own call is dropped, and a read of
  an owed kind first waits until the owed replies came or ``late_reply_s`` passed without
  one (see :mod:`servobus.link.late_replies`). So a value is never older than its call,
  up to that bound; the cost is paid only after a timeout.
* A dead link (closed, reset, unplugged) raises ConnectionLost, also in a call that waits
  for a reply when it happens (at once, not at its deadline), and in every call after.
* Options are checked at construction, per-call ``retries``/``timeout`` at the call
  (ArgumentRangeError): ``timeout`` > 0 and finite, ``retries`` an int >= 0.

Hot path (a poll is a few hundred microseconds of wire time, so host overhead shows): each
read Command gets a plan once (request bytes, the reply key, the parser); replies of streams
that push (TCP, ``sim://``; ``transport.base.PushByteStream``) are framed and matched in the
transport's receive callback (:meth:`AsyncDyn232Client._on_data`; a reply that came in one
chunk takes the framer's whole-packet path), which hands them to the manager's waiting
request; the manager's reply deadline is one lazily re-armed loop timer; 1-byte register
replies (status, config) parse once per distinct value (the results are frozen). Streams
that only ``read()`` (pyserial, the pair) give the manager ``pull`` (one read, fed to the
same callback) and ``flush`` (discard what was buffered before a request).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar, cast

from servobus import checks
from servobus.errors import ArgumentRangeError, ChecksumError
from servobus.families.dmm.command_axis import Request
from servobus.families.dmm.registers import DriveConfig, DriveStatus
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import DEFAULT_LATE_REPLY_S
from servobus.link.stream import StreamClient
from servobus.link.transaction import DEFAULT_RETRIES, check_call
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232 import commands as cmds
from servobus.protocols.dyn232.commands import Command
from servobus.transport.base import ByteStream, Direction

log = logging.getLogger(__name__)

T = TypeVar("T")
#: What a reply is matched on: (drive id, reply function) - all a DYN232M reply carries.
ReplyKey = tuple[int, int]

DEFAULT_TURNAROUND_S = 0.025
MAX_PLANS = 256  # cached read plans per client (reads are a handful of distinct commands)
#: Parsers that are pure and return frozen values: their results are memoised per value.
_MEMO_PARSERS: frozenset[Callable[[int], object]] = frozenset(
    {DriveStatus.from_byte, DriveConfig.from_byte})


class _Plan(Generic[T]):
    """What a transaction needs, computed once per read Command."""

    __slots__ = ("command", "deadline_s", "key", "memo", "parse", "raw", "retry_safe")

    def __init__(self, command: Command[T], raw: bytes, deadline_s: float) -> None:
        self.command = command
        self.raw = raw
        self.deadline_s = deadline_s  # per attempt (plans are dropped when options change)
        want = c.reply_function(command.function, command.value)
        self.key: ReplyKey = (command.drive_id, -1 if want is None else int(want))
        self.retry_safe = command.retry_safe
        self.parse = command.parse
        self.memo: dict[int, T] | None = {} if command.parse in _MEMO_PARSERS else None

    def result(self, value: int) -> T:
        memo = self.memo
        if memo is None or not 0 <= value <= 0x7F:
            return self.parse(value)
        if value in memo:
            return memo[value]
        out = memo[value] = self.parse(value)
        return out


def _own(command: Request[T]) -> Command[T]:
    """A DYN232M Command, or ArgumentRangeError (a request of another protocol)."""
    if not isinstance(command, Command):
        raise ArgumentRangeError(f"not a DYN232M command: {command!r}")
    return command


class AsyncDyn232Client(StreamClient[ReplyKey, bytes, int]):
    """Executes DYN232M Commands on one line (one ByteStream, any number of drives)."""

    def __init__(
        self,
        stream: ByteStream,
        *,
        baud: int = c.BAUD,
        retries: int = DEFAULT_RETRIES,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        timeout: float | None = None,
        query_interval_s: float = 0.0,
        eeprom_guard: EepromGuard | None = None,
        late_reply_s: float = DEFAULT_LATE_REPLY_S,
    ) -> None:
        self._plans: dict[int, _Plan[object]] = {}  # id(command) -> plan (identity checked)
        self._baud = checks.positive_int("baud", baud)
        self._turnaround_s = checks.non_negative_seconds("turnaround_s", turnaround_s)
        self._timeout = checks.optional_seconds("timeout", timeout)
        self._framer = c.Framer()
        # The line's transaction manager: one lane, one transaction at a time.
        super().__init__(stream, stream.write, link="DYN232M link", describe_key=_describe_key,
                         describe_request=_describe_request, trace_request=c.decode,
                         retries=retries, query_interval_s=query_interval_s,
                         late_reply_s=late_reply_s, eeprom_guard=eeprom_guard)

    # ------------------------------------------------------------- options
    # Read plans hold their deadline: changing what it is made of drops them.
    @property
    def baud(self) -> int:
        return self._baud

    @baud.setter
    def baud(self, value: int) -> None:
        self._baud = checks.positive_int("baud", value)
        self._plans.clear()

    @property
    def turnaround_s(self) -> float:
        return self._turnaround_s

    @turnaround_s.setter
    def turnaround_s(self, value: float) -> None:
        self._turnaround_s = checks.non_negative_seconds("turnaround_s", value)
        self._plans.clear()

    @property
    def timeout(self) -> float | None:
        """Per-attempt deadline for every read (None: from the baud rate, see below)."""
        return self._timeout

    @timeout.setter
    def timeout(self, value: float | None) -> None:
        self._timeout = checks.optional_seconds("timeout", value)
        self._plans.clear()

    @property
    def query_interval_s(self) -> float:
        return self.transactions.query_interval_s

    # ------------------------------------------------------------- deadlines
    def reply_deadline_s(self, request_len: int = c.MIN_PACKET) -> float:
        """Per-attempt deadline: request + longest reply on the wire + turnaround."""
        if self.timeout is not None:
            return self.timeout
        return c.wire_time_s(request_len + c.MAX_PACKET, self.baud) + self.turnaround_s

    def worst_case_s(self, request_len: int = c.MIN_PACKET) -> float:
        """Longest a read can take before DriveTimeout (all attempts), pacing excluded."""
        return self.reply_deadline_s(request_len) * (self.retries + 1)

    # ------------------------------------------------------------- execution
    async def execute(self, command: Request[T], *, retries: int | None = None,
                      timeout: float | None = None) -> T:
        """Send ``command``; for reads return the parsed reply, else None."""
        tm = self.transactions
        if retries is not None or timeout is not None:
            check_call(retries, timeout)
        same: object = command  # plans are found by identity
        plan = self._plans.get(id(command))
        if plan is None or plan.command is not same:
            tm.check_alive()  # (a planned read: request() checks)
            own = _own(command)
            if own.kind is c.Kind.INTERNAL:
                raise ArgumentRangeError(f"{own.function.name} is internal to DMM; "
                                         f"never sent")
            raw = own.to_bytes()
            if own.kind is c.Kind.SETTING:
                tm.check_eeprom(own.drive_id, _guard_item(own))
            if not own.expects_reply:
                async with tm.lane():
                    await tm.send(raw)
                return cast(T, None)  # a command without a reply is a Request[None]
            new: _Plan[T] = _Plan(own, raw, self.reply_deadline_s(len(raw)))
            if own.kind is c.Kind.READ:  # a handful of distinct reads: plan once
                if len(self._plans) >= MAX_PLANS:
                    self._plans.clear()
                self._plans[id(command)] = cast("_Plan[object]", new)
            typed = new
        else:
            typed = cast("_Plan[T]", plan)  # planned from this very command
        value = await tm.request(typed.key, typed.raw, retry_safe=typed.retry_safe,
                                 retries=retries,
                                 deadline_s=typed.deadline_s if timeout is None else timeout)
        return typed.result(value)

    async def execute_all(self, commands: Sequence[Command[None]]) -> None:
        """Send no-reply commands back to back without another transaction in between."""
        tm = self.transactions
        tm.check_alive()
        raws = []
        for command in commands:
            if _own(command).expects_reply:
                raise ArgumentRangeError("execute_all is for commands without a reply")
            raws.append(command.to_bytes())
        async with tm.lane():
            for raw in raws:
                await tm.send(raw)

    # ------------------------------------------------------------- reception
    def _on_bytes(self, data: bytes) -> None:
        """Bytes that arrive while no request waits pay owed late replies, if any; else they
        are dropped, as ``flush`` drops them before the next request."""
        tm = self.transactions
        hit = self._framer.whole_reply(data)  # the usual case: the reply, in one chunk
        if hit is not None and tm.answer((hit[0], hit[1]), hit[2]):
            if tm.tracing:
                tm.trace(Direction.RX, c.decode(data))
            return
        if not tm.late_replies and not tm.awaiting_reply:
            if data:
                log.debug("dropped %d byte(s) received between transactions", len(data))
            return
        for event in self._framer.feed(data):
            self._arrival(event)

    def _arrival(self, event: c.FramerEvent) -> None:
        """A framed packet or framing event: an answer, an owed late reply, or a stray."""
        tm = self.transactions
        if type(event) is c.Packet:
            key = (event.drive_id, event.function)
            if tm.answer(key, event.reply_value()) or tm.late(key):
                if tm.tracing:
                    tm.trace(Direction.RX, event)
                return
        tm.trace(Direction.RX, event)
        tm.stray(event)
        if isinstance(event, ChecksumError):
            tm.reject(event)  # the waiting read's attempt failed (its id is not sure)
        # framing errors: keep waiting, the framer resynchronises

    def _reset_receiver(self) -> None:
        self._framer.reset()

    # ------------------------------------------------------------- broadcast / interpolation
    async def broadcast(self, command: Command[None]) -> None:
        """Send a no-reply command to every drive on the line (id 127)."""
        await self.execute(cmds.broadcast(command))

    async def linear_line(self, dx: int, dy: int, dz: int, feedrate: int) -> None:
        """Coordinated 3-axis line (broadcast, drives X/Y/Z = ids 1/2/3 by default)."""
        await self.execute_all(cmds.make_linear_line(dx, dy, dz, feedrate))

    async def circular_arc(self, start: tuple[int, int], end: tuple[int, int], *,
                           plane: int = 0, feedrate: int = 1) -> None:
        await self.execute_all(cmds.make_circular_arc(start, end, plane=plane,
                                                      feedrate=feedrate))


def _describe_key(key: ReplyKey) -> str:
    drive_id, function = key
    return f"{c.function_name(function, from_drive=True)} from drive {drive_id}"


def _describe_request(raw: bytes) -> str:
    packet = c.decode(raw)
    return f"drive {packet.drive_id} to {c.function_name(packet.function, from_drive=False)}"


def _guard_item(command: Command[T]) -> str:
    if command.param is not None:
        return command.param
    if command.function is DmmFunction.SET_DRIVE_CONFIG:
        return "config"
    if command.function is DmmFunction.ASSIGN_DRIVE_ID:
        return "drive_id"
    return command.function.name.lower()

