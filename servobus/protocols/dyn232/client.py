"""DYN232M host client: executes pure ``make_*`` Commands over any ByteStream.

Transaction rules (the manual gives none; these are servobus decisions):

* One transaction at a time per line (asyncio lock): RS485 has one master and replies carry
  no sequence number.
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
  parsed; the read is retried. When every attempt failed, the last failure is raised:
  ChecksumError if the last reply was corrupt, otherwise DriveTimeout.
* Query pacing: ``query_interval_s`` is the minimum time between the starts of two queries
  (commands with a reply). docs/dyn232.md: real drives may drop queries above ~50/s, so 0.02
  is the safe value on hardware; the default 0 is for simulators and fast links. A dropped
  query is still detected (deadline) and retried.
* EEPROM settings (parameters, config, id) pass the EepromGuard before a byte is sent.
* Late replies: a reply to a read that timed out can still come and would match the next
  read of the same kind (id and function are all a reply carries). Each timed-out attempt
  owes a reply; an owed reply that arrives outside its own call is dropped, and a read of
  an owed kind first waits until the owed replies came or ``late_reply_s`` passed without
  one (see :mod:`servobus.axis.late_replies`). So a value is never older than its call,
  up to that bound; the cost is paid only after a timeout.
* A dead link (closed, reset, unplugged) raises ConnectionLost, also in a call that waits
  for a reply when it happens (at once, not at its deadline), and in every call after.
* Options are checked at construction, per-call ``retries``/``timeout`` at the call
  (ArgumentRangeError): ``timeout`` > 0 and finite, ``retries`` an int >= 0.

Hot path (a poll is a few hundred microseconds of wire time, so host overhead shows): each
read Command gets a plan once (request bytes, the reply to match, the parser); replies of
streams that push (TCP, ``sim://``; ``transport.base.PushByteStream``) are framed and
matched in the transport's receive callback, which resolves the waiting future directly;
the reply deadline is one lazily re-armed loop timer, not a timer per call; 1-byte register
replies (status, config) parse once per distinct value (the results are frozen). Streams
that only ``read()`` (pyserial, the pair) take the pull loop with the same rules.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from servobus.axis import checks
from servobus.axis.base import AxisTraceHook
from servobus.axis.command_axis import CommandAxis, CommandSet
from servobus.axis.eeprom_guard import EepromGuard
from servobus.axis.late_replies import DEFAULT_LATE_REPLY_S, LateReplies
from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    ConnectionLost,
    DriveTimeout,
    ProtocolError,
)
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import DriveConfig, DriveStatus
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232 import commands as cmds
from servobus.protocols.dyn232.commands import Command
from servobus.transport.base import ByteStream, Direction, set_receiver

log = logging.getLogger(__name__)

DEFAULT_TURNAROUND_S = 0.025
DEFAULT_RETRIES = 2
MAX_PLANS = 256  # cached read plans per client (reads are a handful of distinct commands)
#: Parsers that are pure and return frozen values: their results are memoised per value.
_MEMO_PARSERS: frozenset[Callable[[int], Any]] = frozenset(
    {DriveStatus.from_byte, DriveConfig.from_byte})


class _Plan:
    """What a transaction needs, computed once per read Command."""

    __slots__ = ("command", "drive_id", "key", "memo", "parse", "raw", "retry_safe",
                 "want_fn")

    def __init__(self, command: Command, raw: bytes) -> None:
        self.command = command
        self.raw = raw
        self.drive_id = command.drive_id
        want = c.reply_function(command.function, command.value)
        self.want_fn = -1 if want is None else int(want)
        self.key = (self.drive_id, self.want_fn)  # what a reply is matched on
        self.retry_safe = command.retry_safe
        parse = command.parse
        self.parse: Callable[[int], Any] | None = None if parse is cmds._identity else parse
        self.memo: dict[int, Any] | None = {} if parse in _MEMO_PARSERS else None

    def result(self, value: int) -> Any:
        parse = self.parse
        if parse is None:
            return value
        memo = self.memo
        if memo is None or not 0 <= value <= 0x7F:
            return parse(value)
        out = memo.get(value)
        if out is None:
            out = memo[value] = parse(value)
        return out


@dataclass
class LineStats:
    """Counters of one line (all drives on it)."""

    sent: int = 0
    replies: int = 0
    retries: int = 0
    timeouts: int = 0
    checksum_errors: int = 0
    framing_errors: int = 0
    unmatched: int = 0


class AsyncDyn232Client:
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
        self.stream = stream
        self.baud = checks.positive_int("baud", baud)
        self.retries = checks.count("retries", retries)
        self.turnaround_s = checks.non_negative_seconds("turnaround_s", turnaround_s)
        self.timeout = checks.optional_seconds("timeout", timeout)
        self.query_interval_s = checks.non_negative_seconds("query_interval_s",
                                                            query_interval_s)
        #: Replies owed by timed-out reads (``late_replies.late``, ``.given_up``).
        self.late_replies: LateReplies[tuple[int, int]] = LateReplies(
            checks.non_negative_seconds("late_reply_s", late_reply_s), _describe_key)
        self.guard = eeprom_guard if eeprom_guard is not None else EepromGuard()
        self.stats = LineStats()
        self._framer = c.Framer()
        self._events: deque[c.FramerEvent] = deque()
        self._lock = asyncio.Lock()
        self._hooks: list[AxisTraceHook] = []
        self._last_query = -1e9
        self._closed = False
        self._dead: ConnectionLost | None = None  # set when closed or the link died
        self._plans: dict[int, _Plan] = {}  # id(command) -> plan (identity checked)
        # Push reception: the transaction waiting for a reply (future + plan), if any.
        self._push = set_receiver(stream, self._on_data)
        self._waiting: asyncio.Future[int | None] | None = None
        self._waiting_plan: _Plan | None = None
        self._deadline = 0.0
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = 0.0

    # ------------------------------------------------------------- tracing
    def add_trace(self, hook: AxisTraceHook) -> None:
        """``hook(direction, item, t)``: every packet sent/received (decoded) and every error."""
        self._hooks.append(hook)

    def _trace(self, direction: Direction, item: object) -> None:
        t = time.monotonic()
        for hook in self._hooks:
            hook(direction, item, t)

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
    async def execute(self, command: Command, *, retries: int | None = None,
                      timeout: float | None = None) -> Any:
        """Send ``command``; for reads return the parsed reply, else None."""
        if self._dead is not None:
            raise ConnectionLost(str(self._dead))
        if retries is not None:
            checks.count("retries", retries)
        if timeout is not None:
            checks.seconds("timeout", timeout)
        plan = self._plans.get(id(command))
        if plan is None or plan.command is not command:
            if command.kind is c.Kind.INTERNAL:
                raise ArgumentRangeError(f"{command.function.name} is internal to DMM; "
                                         f"never sent")
            raw = command.to_bytes()
            if command.kind is c.Kind.SETTING:
                self.guard.check(command.drive_id, _guard_item(command))
            if not command.expects_reply:
                async with self._lock:
                    await self._send(raw)
                return None
            plan = _Plan(command, raw)
            if command.kind is c.Kind.READ:  # a handful of distinct reads: plan once
                if len(self._plans) >= MAX_PLANS:
                    self._plans.clear()
                self._plans[id(command)] = plan
        async with self._lock:
            return await self._transact(plan, retries, timeout)

    async def execute_all(self, commands: list[Command]) -> None:
        """Send no-reply commands back to back without another transaction in between."""
        for command in commands:
            if command.expects_reply:
                raise ArgumentRangeError("execute_all is for commands without a reply")
            command.to_bytes()
        async with self._lock:
            for command in commands:
                await self._send(command.to_bytes())

    async def _send(self, raw: bytes) -> None:
        if self._hooks:
            self._trace(Direction.TX, c.decode(raw))
        self.stats.sent += 1
        try:
            await self.stream.write(raw)
        except OSError as exc:
            raise self._link_failed(exc) from exc

    def _link_failed(self, exc: BaseException) -> BaseException:
        """``exc`` from the stream as the client raises it; a dead link stays dead."""
        out = checks.lost(exc, "DYN232M link lost")
        if isinstance(out, ConnectionLost) and self._dead is None:
            self._dead = out
            self.late_replies.hang_up(ConnectionLost(str(out)))
            log.debug("link lost: %s", out)
        return out

    async def _transact(self, plan: _Plan, retries: int | None,
                        timeout: float | None) -> Any:
        command = plan.command
        n_retries = (self.retries if retries is None else retries) if plan.retry_safe else 0
        per_try = timeout if timeout is not None else self.reply_deadline_s(len(plan.raw))
        if self._events:
            self._settle_events()
        late = self.late_replies
        if late and late.owed(plan.key):
            await self._drain(plan.key)
        last: ProtocolError | DriveTimeout | None = None
        for attempt in range(n_retries + 1):
            if attempt:
                self.stats.retries += 1
                log.debug("retry %d of %d: %s to drive %d after %s", attempt, n_retries,
                          command.function.name, command.drive_id, type(last).__name__)
            if self.query_interval_s > 0:
                await self._pace()
            else:
                self._last_query = time.monotonic()
            if late and not self._push:
                await self._absorb_buffered()
            self._discard_pending()
            try:
                if self._push:
                    value = await self._exchange(plan, per_try)
                else:
                    await self._send(plan.raw)
                    value = (await self._await_reply(command, per_try)).reply_value()
            except DriveTimeout as exc:
                late.owe(plan.key)  # its reply may still come: never to a later call
                last = exc
                continue
            except ChecksumError as exc:
                last = exc
                continue
            self.stats.replies += 1
            return plan.result(value)
        assert last is not None
        if isinstance(last, DriveTimeout):
            raise DriveTimeout(
                f"no reply from drive {command.drive_id} to {command.function.name} "
                f"after {n_retries + 1} attempt(s) of {per_try * 1000:.1f} ms"
            )
        raise last

    async def _pace(self) -> None:
        """Wait until ``query_interval_s`` has passed since the previous query started."""
        wait = self._last_query + self.query_interval_s - time.monotonic()
        if wait > 0:
            await asyncio.sleep(wait)
        self._last_query = time.monotonic()

    # ------------------------------------------------------------- push reception
    async def _exchange(self, plan: _Plan, per_try: float) -> int:
        """Send the request; the stream's receive callback (:meth:`_on_data`) resolves the
        future with the reply value (None: deadline passed)."""
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[int | None] = loop.create_future()
        self._waiting, self._waiting_plan = fut, plan
        try:
            if self._hooks:
                self._trace(Direction.TX, c.decode(plan.raw))
            self.stats.sent += 1
            try:
                await self.stream.write(plan.raw)  # an unpaced sim:// line answers here
            except OSError as exc:
                raise self._link_failed(exc) from exc
            if not fut.done():
                self._deadline = deadline = loop.time() + per_try
                if self._timer is None or self._timer_at > deadline:
                    self._arm(loop, deadline)
            value = await fut
        finally:
            self._waiting = self._waiting_plan = None
        if value is None:
            raise self._timeout(plan.command, per_try)
        return value

    def _arm(self, loop: asyncio.AbstractEventLoop, when: float) -> None:
        """One timer serves every transaction: when it fires early (it was set for an
        earlier transaction) it re-arms for the current deadline. Saves a timer per call."""
        if self._timer is not None:
            self._timer.cancel()
        self._timer_at = when
        self._timer = loop.call_at(when, self._on_timer, loop)

    def _on_timer(self, loop: asyncio.AbstractEventLoop) -> None:
        self._timer = None
        fut = self._waiting
        if fut is None or fut.done():
            return
        if loop.time() >= self._deadline:
            fut.set_result(None)  # None = deadline passed
        else:
            self._arm(loop, self._deadline)

    def _on_data(self, data: bytes | None) -> None:
        """Receive callback of push streams. Bytes that arrive while no transaction waits
        pay owed late replies, if any; else they are dropped, as ``discard_input()`` drops
        them before the next request. ``None``: the stream closed or failed."""
        fut = self._waiting
        if data is None:
            self._link_failed(ConnectionLost("stream closed"))
            if fut is not None and not fut.done():
                fut.set_exception(ConnectionLost("stream closed while waiting for a reply"))
            return
        if fut is None or fut.done():
            if self.late_replies:
                for event in self._framer.feed(data):
                    self._arrival(event)
            elif data:
                log.debug("dropped %d byte(s) received between transactions", len(data))
            return
        plan = self._waiting_plan
        assert plan is not None
        hit = self._framer.whole_reply(data)  # the usual case: the reply, in one chunk
        if hit is not None and hit[0] == plan.drive_id and hit[1] == plan.want_fn:
            if self._hooks:
                self._trace(Direction.RX, c.decode(data))
            fut.set_result(hit[2])
            return
        for event in self._framer.feed(data):
            if fut.done():
                self._events.append(event)  # after the reply: stray at the next request
            elif type(event) is c.Packet:
                if event.drive_id == plan.drive_id and event.function == plan.want_fn:
                    if self._hooks:
                        self._trace(Direction.RX, event)
                    fut.set_result(event.reply_value())
                else:
                    self._arrival(event)
            elif isinstance(event, ChecksumError):
                self._note_stray(event)
                fut.set_exception(event)
            else:
                self._note_stray(event)  # framing: keep waiting, the framer resyncs

    def _discard_pending(self) -> None:
        """Stale bytes (late replies, noise) must not answer the next request."""
        if not self._push:  # a push stream buffers nothing; _on_data drops stale bytes
            self.stream.discard_input()
        self._framer.reset()
        if self._events:
            self._settle_events()

    def _settle_events(self) -> None:
        """Packets framed after the last reply: owed late replies or strays."""
        events = self._events
        while events:
            self._arrival(events.popleft())

    def _arrival(self, event: c.FramerEvent) -> None:
        """A packet (or framing event) that is not the answer of a waiting request."""
        if type(event) is c.Packet and self.late_replies.take(
                (event.drive_id, event.function)):
            self._trace(Direction.RX, event)
            return
        self._note_stray(event)

    def _note_stray(self, event: c.FramerEvent) -> None:
        self._trace(Direction.RX, event)
        if isinstance(event, ChecksumError):
            self.stats.checksum_errors += 1
        elif isinstance(event, ProtocolError):
            self.stats.framing_errors += 1
        else:
            self.stats.unmatched += 1
        log.debug("stray %s", event)

    # ------------------------------------------------------------- late replies
    async def _drain(self, key: tuple[int, int]) -> None:
        """Send nothing for ``key`` until its owed replies came or went quiet."""
        if self._push:
            self._framer.reset()
            await self.late_replies.drain([key])
            return
        late = self.late_replies
        left = late.wait_s([key])
        if left > 0:
            late.drains += 1
            log.debug("waiting up to %.0f ms for late replies %s before sending",
                      left * 1000, _describe_key(key))
        while left > 0:
            try:
                async with asyncio.timeout(left):
                    data = await self.stream.read()
            except TimeoutError:
                pass
            except OSError as exc:
                raise self._link_failed(exc) from exc
            else:
                for event in self._framer.iter_feed(data):
                    self._arrival(event)
            left = late.wait_s([key])

    async def _absorb_buffered(self) -> None:
        """Pull streams: frame what is already buffered (owed late replies pay their
        debt) instead of discarding it unseen. Does not wait for more."""
        while True:
            try:
                async with asyncio.timeout(0):
                    data = await self.stream.read()
            except TimeoutError:
                return
            except OSError as exc:
                raise self._link_failed(exc) from exc
            for event in self._framer.iter_feed(data):
                self._arrival(event)

    async def _await_reply(self, command: Command, per_try: float) -> c.Packet:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + per_try
        want_fn = c.reply_function(command.function, command.value)
        while True:
            while self._events:
                event = self._events.popleft()
                if isinstance(event, c.Packet):
                    if event.drive_id == command.drive_id and event.function == want_fn:
                        if self._hooks:
                            self._trace(Direction.RX, event)
                        return event
                    self._arrival(event)
                elif isinstance(event, ChecksumError):
                    self._note_stray(event)
                    raise event
                else:
                    self._note_stray(event)  # framing: keep waiting, the framer resyncs
            remaining = deadline - loop.time()
            if remaining <= 0:
                raise self._timeout(command, per_try)
            try:
                async with asyncio.timeout(remaining):
                    data = await self.stream.read()
            except TimeoutError:
                raise self._timeout(command, per_try) from None
            except OSError as exc:
                raise self._link_failed(exc) from exc
            self._events.extend(self._framer.iter_feed(data))

    def _timeout(self, command: Command, per_try: float) -> DriveTimeout:
        self.stats.timeouts += 1
        exc = DriveTimeout(f"no reply from drive {command.drive_id} to "
                           f"{command.function.name} within {per_try * 1000:.1f} ms")
        self._trace(Direction.RX, exc)
        log.debug("%s", exc)
        return exc

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._dead is None:
            self._dead = ConnectionLost("client is closed")
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        await self.stream.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------- broadcast / interpolation
    async def broadcast(self, command: Command) -> None:
        """Send a no-reply command to every drive on the line (id 127)."""
        await self.execute(cmds.broadcast(command))

    async def linear_line(self, dx: int, dy: int, dz: int, feedrate: int) -> None:
        """Coordinated 3-axis line (broadcast, drives X/Y/Z = ids 1/2/3 by default)."""
        await self.execute_all(cmds.make_linear_line(dx, dy, dz, feedrate))

    async def circular_arc(self, start: tuple[int, int], end: tuple[int, int], *,
                           plane: int = 0, feedrate: int = 1) -> None:
        await self.execute_all(cmds.make_circular_arc(start, end, plane=plane,
                                                      feedrate=feedrate))


def _describe_key(key: tuple[int, int]) -> str:
    drive_id, function = key
    return f"{c.function_name(function, from_drive=True)} from drive {drive_id}"


def _guard_item(command: Command) -> str:
    if command.param is not None:
        return command.param
    if command.function is c.HostFunction.SET_DRIVE_CONFIG:
        return "config"
    if command.function is c.HostFunction.ASSIGN_DRIVE_ID:
        return "drive_id"
    return command.function.name.lower()


class Dyn232Axis(CommandAxis):
    """One DYN2/DC2/DYN4 drive on a DYN232M line (everything is CommandAxis).

    The torque readout counts milliamperes (a servobus decision, docs/dyn232.md).
    """

    commands: ClassVar[CommandSet] = cmds
    protocol_name = "dyn232"
    drive_id_range = range(c.FACTORY_ID, c.MAX_DRIVE_ID + 1)
    amps_per_torque_unit = 1.0 / U.DYN232_TORQUE_UNITS_PER_A
