"""DYN CAN host client over any python-can bus, and DynCanAxis (the shared Axis API).

``open_can_axis("pcan:PCAN_USBBUS1", drive_id=1, bitrate=500000)`` opens the bus the way
python-can users write it (extra keywords go to ``can.Bus``) and returns an AsyncAxis;
``connect(can=...)`` calls it. One :class:`AsyncDynCanClient` per bus serves any number of
drives (``axis.sibling(id)``, :meth:`AsyncDynCanClient.sync_move`, streaming).

Transaction rules (servobus decisions; the manual gives none). The rules every protocol
shares (deadline, retries, stats, trace, EEPROM guard, late replies, dead links) are
:mod:`servobus.link.transaction`'s; ``client.transactions`` is the bus's manager
(``stats``, ``late_replies`` and ``guard`` are its). How DYN CAN applies them:

* A reply matches a pending read when its identifier (drive id, function) and its data
  length fit the table (a read request has a different length from its reply, so another
  host's request on the same identifier is not taken for a reply). A read sent to the
  broadcast id 0 accepts the first reply from any drive.
* Reads to one drive run one at a time (one lane per drive id: replies carry no sequence
  number); different drives are served concurrently. No-reply commands are sent at once.
* Per-attempt deadline ``timeout`` (default 50 ms: a drive answers within about a
  millisecond at 500 kbit/s; the margin covers USB adapters, socketcand over TCP and a
  loaded host). Only reads are re-sent, at most ``retries`` times (default 2); motion and
  settings are sent exactly once.
* Drive Error 0xFF fails the read in flight to that drive (not re-sent: the drive refused
  it), or is raised as DriveError by that drive's next call (a no-reply command cannot be
  answered in-line). Counted in ``stats.error_replies``; alarm pushes in ``stats.alarms``.
* Drive Error 0xEE (alarm push) calls every ``on_alarm`` callback at once and raises a
  DriveAlarm on that drive's next call (once); Position Direct streaming stops on it.
* EEPROM writes (config, id, parameter groups 1 and 3) pass the EepromGuard first. Group 2
  (max speed / accel) is exempt: the drive keeps it in RAM after 10 saves per power-on.
* Late replies: a reply carries its identifier only, so a read that timed out owes its reply
  to nobody else: each timed-out attempt owes one reply per (drive id, function); an owed
  frame that arrives while no read of its identifier waits is dropped, and a read of an
  owed identifier first waits until the owed frames came or ``late_reply_s`` passed
  without one (:mod:`servobus.link.late_replies`). A value is never older than its call,
  up to that bound.
* A dead bus (closed, socketcand gone, adapter error) raises ConnectionLost, at once in the
  reads that wait when it happens, and in every call after.
* Options are checked at construction and per-call ``retries``/``timeout`` at the call
  (ArgumentRangeError): ``timeout`` > 0 and finite, ``retries`` an int >= 0.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeVar, cast

from servobus import checks
from servobus.errors import (
    ArgumentRangeError,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    ServobusError,
)
from servobus.families.dmm.command_axis import Request
from servobus.link.can import CanClient
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import DEFAULT_LATE_REPLY_S
from servobus.link.stats import StreamStats, TransactionStats
from servobus.link.transaction import DEFAULT_RETRIES, TransactionManager, check_call
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan import commands as cmds
from servobus.protocols.dyncan.commands import CanCommand
from servobus.transport.base import Direction
from servobus.transport.can_bus import AsyncCanBus, CanFrame, FramePort

log = logging.getLogger(__name__)

T = TypeVar("T")
#: What a reply is matched on: (drive id, function) - its 11-bit identifier.
ReplyKey = tuple[int, int]

DEFAULT_TIMEOUT_S = 0.05
ID_REINIT_S = 0.010  # section 6: wait 10 ms for the drive to re-initialise its CAN port
_GUARD_EXEMPT = frozenset({"max_speed", "max_accel"})

AlarmCallback = Callable[[int], None]  # called with the alarming drive's id
#: The counters of a bus (the one stats class of every protocol).
BusStats = TransactionStats


def _describe_key(key: ReplyKey) -> str:
    drive_id, function = key
    return f"{c.function_name(function)} from drive {drive_id}"


def _describe_request(frame: c.Frame) -> str:
    return f"drive {frame.drive_id} to {c.function_name(frame.function)}"


def _own(command: Request[T]) -> CanCommand[T]:
    """A DYN CAN command, or ArgumentRangeError (a request of another protocol)."""
    if not isinstance(command, CanCommand):
        raise ArgumentRangeError(f"not a DYN CAN command: {command!r}")
    return command


class AsyncDynCanClient(CanClient[ReplyKey, c.Frame, c.Frame]):
    """Executes CanCommands on one CAN bus (any FramePort)."""

    def __init__(self, port: FramePort, *, timeout: float | None = None,
                 retries: int = DEFAULT_RETRIES, eeprom_guard: EepromGuard | None = None,
                 on_alarm: AlarmCallback | None = None,
                 late_reply_s: float = DEFAULT_LATE_REPLY_S) -> None:
        checked = checks.optional_seconds("timeout", timeout)
        self.timeout = DEFAULT_TIMEOUT_S if checked is None else checked
        if on_alarm is not None and not callable(on_alarm):
            raise ArgumentRangeError(f"on_alarm must be callable, got {on_alarm!r}")
        self._alarm_callbacks: list[AlarmCallback] = [on_alarm] if on_alarm else []
        self._pending: dict[int, ServobusError] = {}
        # the bus's transaction manager: one lane per drive id
        super().__init__(port, TransactionManager(
            self._write, link="CAN bus", describe_key=_describe_key,
            describe_request=_describe_request, retries=retries, late_reply_s=late_reply_s,
            eeprom_guard=eeprom_guard, owed_keys=self._owed_keys), name="dyncan-rx")

    def reply_deadline_s(self) -> float:
        """Per-attempt deadline of a read (``timeout``: a frame each way at 1 Mbit/s is
        ~0.1 ms; the rest is the drive's reply time and the adapter's latency)."""
        return self.timeout

    # ------------------------------------------------------------- hooks
    def on_alarm(self, callback: AlarmCallback) -> None:
        """``callback(drive_id)`` runs on the loop when a drive pushes Drive Error 0xEE."""
        self._alarm_callbacks.append(callback)

    # ------------------------------------------------------------- receiving
    def _on_can_frame(self, raw: CanFrame) -> None:
        tm = self.transactions
        if raw.is_extended_id or raw.arbitration_id > c.MAX_ARBITRATION_ID:
            tm.stray(raw)
            return
        self._dispatch(c.decode(raw.arbitration_id, raw.data[:c.MAX_DATA]))

    def _dispatch(self, frame: c.Frame) -> None:
        tm = self.transactions
        if tm.tracing:
            tm.trace(Direction.RX, frame)
        function = frame.function
        if function == c.Function.DRIVE_ERROR and len(frame.data) == 1:
            self._drive_error(frame.drive_id, frame.data[0])
            return
        if c.is_reply_shape(frame):
            key = (frame.drive_id, function)
            if tm.answer(key, frame) or tm.answer((c.BROADCAST_ID, function), frame):
                return
            if tm.late_replies and (tm.late(key) or tm.late((c.BROADCAST_ID, function))):
                return
        tm.stray(frame)

    def _drive_error(self, drive_id: int, code: int) -> None:
        tm = self.transactions
        if code == c.DriveErrorCode.ALARM:
            tm.stats.alarms += 1
            self._pending[drive_id] = DriveAlarm(
                f"drive {drive_id} pushed an alarm (Drive Error 0xEE); read the status for "
                "its code; a reset clears it", code=code, drive_id=drive_id)
            for cb in list(self._alarm_callbacks):
                cb(drive_id)
            return
        tm.stats.error_replies += 1
        err = DriveError(f"drive {drive_id} answered Drive Error 0x{code:02x} (invalid data)",
                         code=code, drive_id=drive_id)
        for key in tm.waiting_keys():
            if key[0] in (drive_id, c.BROADCAST_ID) and tm.reject(err, key):
                return
        self._pending[drive_id] = err

    def raise_pending(self, drive_id: int) -> None:
        """Raise (once) an alarm push or Drive Error that arrived for ``drive_id``."""
        if not self._pending:
            return
        if drive_id == c.BROADCAST_ID:
            key = next(iter(self._pending))
        elif drive_id in self._pending:
            key = drive_id
        else:
            return
        raise self._pending.pop(key)

    # ------------------------------------------------------------- sending
    async def _write(self, frame: c.Frame) -> None:
        await self.port.send(*c.encode(frame))

    def _guard(self, command: CanCommand[T]) -> None:
        if command.kind is c.Kind.SETTING and command.guard_item:
            for item in command.guard_item.split(","):
                if item not in _GUARD_EXEMPT:
                    self.transactions.check_eeprom(command.drive_id, item)

    async def execute(self, command: Request[T], *, retries: int | None = None,
                      timeout: float | None = None) -> T:
        """Send ``command``; for reads return the parsed reply, else None."""
        tm = self.transactions
        tm.check_alive()
        if retries is not None or timeout is not None:
            check_call(retries, timeout)
        own = _own(command)
        drive_id = own.drive_id
        if self._pending:
            self.raise_pending(drive_id)
        if own.kind is c.Kind.SETTING:
            self._guard(own)
        if not own.expects_reply:
            await tm.send(own.frame)
            return cast(T, None)  # a command without a reply is a Request[None]
        reply = await tm.request((drive_id, own.frame.function), own.frame,
                                 deadline_s=self.timeout if timeout is None else timeout,
                                 retry_safe=own.retry_safe, retries=retries, lane=drive_id)
        return own.parse(reply)

    def _owed_keys(self, key: ReplyKey) -> list[ReplyKey]:
        """Owed keys whose late frames this read could take for its answer: its own and a
        broadcast read's of the same function; for a broadcast read, every drive's."""
        drive_id, function = key
        if drive_id == c.BROADCAST_ID:
            return self.late_replies.keys(lambda k: k[1] == function)
        return [key, (c.BROADCAST_ID, function)]

    async def execute_all(self, commands: Iterable[CanCommand[None]]) -> None:
        """Send no-reply commands back to back (checked and guarded first)."""
        tm = self.transactions
        tm.check_alive()
        batch = [_own(command) for command in commands]
        for command in batch:
            if command.expects_reply:
                raise ArgumentRangeError("execute_all is for commands without a reply")
            self.raise_pending(command.drive_id)
        for command in batch:
            self._guard(command)
        for command in batch:
            await tm.send(command.frame)

    # ------------------------------------------------------------- multi-axis helpers
    async def sync_move(self, targets: Mapping[int, int], *, relative: bool = False) -> None:
        """Load each drive's synchronized move, then start all with one broadcast trigger."""
        loads = [cmds.make_sync_load(i, v, relative=relative) for i, v in targets.items()]
        await self.execute_all([*loads, cmds.make_sync_trigger(relative=relative)])

    async def stream_position_direct(self, steps: Mapping[int, Iterable[int]],
                                     period: float) -> StreamStats:
        """Send one Position Direct step per drive every ``period`` seconds.

        Slots are ``t0 + k x period`` on the loop clock (no drift; asyncio sleeps are
        millisecond-accurate, so single slots jitter but the rate holds). Each tick's values
        are range-checked before any of its frames is sent; an alarm push or Drive Error
        for a streamed drive stops the stream with that error.
        """
        checks.seconds("period", period)
        iters = {cmds.check_drive_id(i, allow_broadcast=False): iter(s)
                 for i, s in steps.items()}
        stats = StreamStats()
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        while iters:
            tick: list[CanCommand[None]] = []
            for drive_id, it in list(iters.items()):
                try:
                    tick.append(cmds.make_position_direct(drive_id, next(it)))
                except StopIteration:
                    del iters[drive_id]
            if not tick:
                break
            due = t0 + stats.cycles * period
            delay = due - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            elif -delay > period:
                stats.late_cycles += 1
            stats.max_lateness_s = max(stats.max_lateness_s, -delay)
            for command in tick:
                self.raise_pending(command.drive_id)
            for command in tick:
                await self.transactions.send(command.frame)
            stats.frames += len(tick)
            stats.cycles += 1
        stats.elapsed_s = loop.time() - t0
        return stats

    async def heartbeat(self, drive_id: int) -> int:
        """One diagnostic-counter read (the counter steps by 1 per read, 255 -> 0)."""
        return await self.execute(cmds.make_read_counter(drive_id))

    def start_heartbeat(self, drive_id: int, period: float,
                        on_lost: Callable[[int, BaseException], None]) -> Heartbeat:
        cmds.check_drive_id(drive_id, allow_broadcast=False)
        checks.seconds("period", period)
        hb = Heartbeat(self, drive_id, period, on_lost)
        hb.start()
        return hb


class Heartbeat:
    """Periodic diagnostic-counter reads; ``on_lost(drive_id, exc)`` when a read fails.

    ``gaps`` counts readings that did not follow the previous one by exactly 1 (another
    host reading the counter, or a drive restart).
    """

    def __init__(self, client: AsyncDynCanClient, drive_id: int, period: float,
                 on_lost: Callable[[int, BaseException], None]) -> None:
        self.client = client
        self.drive_id = drive_id
        self.period = period
        self.on_lost = on_lost
        self.beats = 0
        self.gaps = 0
        self.last: int | None = None
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run())

    async def _run(self) -> None:
        while True:
            try:
                value = await self.client.heartbeat(self.drive_id)
            except (DriveTimeout, DriveError, DriveAlarm, ConnectionError) as exc:
                self.on_lost(self.drive_id, exc)
                if isinstance(exc, ConnectionError):
                    return
            else:
                if self.last is not None and value != (self.last + 1) & 0xFF:
                    self.gaps += 1
                self.last = value
                self.beats += 1
            await asyncio.sleep(self.period)

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task


_CLIENT_OPTIONS = ("retries", "eeprom_guard", "on_alarm", "late_reply_s")


async def open_can_client(can: str, *, timeout: float | None = None,
                          **options: Any) -> AsyncDynCanClient:
    """Open ``can`` ("INTERFACE:CHANNEL"); keywords other than the client's go to can.Bus."""
    client_kw = {k: options.pop(k) for k in _CLIENT_OPTIONS if k in options}
    port = await AsyncCanBus.open(can, **options)
    try:
        return AsyncDynCanClient(port, timeout=timeout, **client_kw)
    except BaseException:  # a bad option (ArgumentRangeError): nothing sent, bus released
        await port.close()
        raise

