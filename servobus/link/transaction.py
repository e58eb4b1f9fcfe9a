"""One transaction policy for every protocol client (issue #9): read this to write a client.

Your client keeps what is its protocol's own: it encodes requests, frames and decodes what
arrives, and knows the *key* a reply is matched on (e.g. ``(drive id, reply function)``: a
hashable value that a request and its reply both give). A :class:`TransactionManager` keeps
the rules every client must follow, in one place:

* **Deadline and retries.** Each attempt waits ``deadline_s`` for its reply, measured from
  when the request's bytes have left (``write`` returned). Only ``retry_safe`` requests
  (reads) are re-sent, up to ``retries`` times; motion, settings and actions are written
  exactly once and never re-sent. No reply in any attempt: DriveTimeout; a corrupt reply
  (``reject(ChecksumError)``) fails its attempt, and ChecksumError is raised when the last
  attempt failed that way. Any other error a receive path rejects with ends the call.
* **Pacing at the wire.** ``query_interval_s`` is the least time from the moment one
  request's bytes have left (its ``write`` returned or drained) to the start of the next
  request's write. The clock is stamped after the write, never when the send is decided,
  so a loaded host cannot squeeze two requests closer than the interval. Retries are paced
  too; :meth:`send` (commands without a reply) is not.
* **Lanes.** Requests of one lane run one at a time (``lane=None``: the whole link, as on an
  RS-485 line with one master; a CAN client uses the drive id). One request per key may
  wait at a time: give requests that share a key the same lane. ``async with
  manager.lane(x)`` keeps a no-reply command out of a transaction in progress.
* **Stats** (:class:`TransactionStats`, the same fields on every protocol) and **trace
  hooks** (``hook(direction, item, t)``: the manager traces each request it writes, as
  ``trace_request(payload)``, and every timeout; your receive path traces what it decodes).
* **EEPROM guard**: call :meth:`check_eeprom` for each EEPROM-backed item a command writes,
  before sending it (refusals are logged at warning level).
* **Late replies** (:mod:`servobus.link.late_replies`): an attempt that timed out owes its
  reply; the next request of an owed key first waits until it came or ``late_reply_s``
  passed quiet, so a late reply never answers a later call.
* **A stalled host is not a silent drive.** When the deadline timer fires more than
  :data:`STALL_S` after it was due, the process (or its loop) was stalled: a reply that
  came meanwhile may still wait a few loop turns for its delivery (a socket's bytes are
  read in the same turn, an in-process virtual drive's reply takes several). Each attempt
  overdue then gets :data:`GRACE_TURNS` loop turns once before it times out (turns, not
  time: a second stall within a grace of time would waste it). Decision: seen under load,
  a stall of seconds timed out requests sent once (a sync signal, a move) whose replies
  were already on their way; a drive that never answers is declared so a few loop turns
  later, only after a stall.
* **Dead links**: :meth:`lost` (the medium failed or hung up) makes every waiting request and
  every later call raise ConnectionLost at once.

A client, in outline (DYN232M and DYN CAN in ``servobus/protocols/`` are complete ones)::

    self.transactions = TransactionManager[Key, bytes, int](
        self._write,                      # async: hand one request to the medium
        link="Modbus RTU link", describe_key=..., describe_request=..., trace_request=...,
        retries=retries, query_interval_s=..., late_reply_s=..., eeprom_guard=guard,
        pull=None,                        # or a coroutine: read once, feed the receive path
        flush=self._flush)                # before each attempt: drop partial input

    async def execute(self, command, *, retries=None, timeout=None):
        check_call(retries, timeout)      # per-call knobs, before anything is sent
        tm = self.transactions
        tm.check_alive()
        if not command.expects_reply:
            await tm.send(command.raw)    # exactly once, never waited on
            return None
        return await tm.request(key_of(command), command.raw, deadline_s=...,
                                retry_safe=command.is_read, retries=retries)

    def _on_data(self, data):             # receive path: push callback or ``pull``
        if data is None:
            self.transactions.lost(ConnectionLost("stream closed")); return
        for reply in self._framer.feed(data):   # your decoding, your tracing
            key = key_of(reply)
            if not (tm.answer(key, reply) or tm.late(key)):
                tm.stray(reply)           # counted as checksum/framing error or unmatched
        # a corrupt reply during a wait: tm.reject(ChecksumError(...)) (retried)

Media that push received data call the receive path themselves. For media that can only be
read (pyserial, the pull-only pair) pass ``pull``: one ``read()`` fed to the receive path;
the manager calls it while a reply or a late reply is due, and (only when late replies are
owed) to frame what is already buffered before ``flush`` drops the rest. The manager runs
on one event loop; nothing in it blocks.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable, Hashable, Iterable
from typing import Generic, TypeVar

from servobus import checks
from servobus.errors import (
    ChecksumError,
    ConnectionLost,
    DriveTimeout,
    EepromGuardError,
    ProtocolError,
)
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import DEFAULT_LATE_REPLY_S, LateReplies
from servobus.link.stats import TransactionStats
from servobus.transport.base import Direction

log = logging.getLogger(__name__)

#: ``hook(direction, item, t)``: decoded requests/replies and errors a link traces (the same
#: shape as the Axis's ``AxisTraceHook``; transport.base.TraceHook is the raw bytes one).
LinkTraceHook = Callable[[Direction, object, float], None]

K = TypeVar("K", bound=Hashable)  # what a reply is matched on
P = TypeVar("P")  # a request as the medium takes it (bytes, a CAN frame, ...)
V = TypeVar("V")  # a reply as the receive path hands it over (a value, a frame, ...)

#: Default re-sends of a read after its first attempt (servobus decision, docs/axis.md).
DEFAULT_RETRIES = 2
#: A deadline timer firing this late means the host stalled (asyncio timers are otherwise
#: up to about a millisecond late: epoll rounds to milliseconds).
STALL_S = 0.02
#: Loop turns an overdue attempt gets once after a stall: the delivery of a reply that
#: came meanwhile takes a few (an in-process virtual drive's: three; a socket's: none).
GRACE_TURNS = 8


def check_call(retries: object, timeout: object) -> None:
    """Per-call knobs, before anything is sent: ``retries`` an int >= 0, ``timeout`` > 0 and
    finite (each may be None: the client's default)."""
    if retries is not None:
        checks.count("retries", retries)
    if timeout is not None:
        checks.seconds("timeout", timeout)


class _Expired(Exception):
    """An attempt's deadline passed (internal: becomes DriveTimeout)."""


class TransactionManager(Generic[K, P, V]):
    """The transaction rules of one link (see the module docstring).

    ``write(payload)`` hands one request to the medium and returns once its bytes have left.
    ``describe_key(key)`` names a reply for logs ("IS_STATUS from drive 3");
    ``describe_request(payload)`` names who should answer what, for errors ("drive 3 to
    READ_DRIVE_STATUS"); ``trace_request(payload)`` is what trace hooks get for a request
    (default: the payload). ``owed_keys(key)``: the owed keys whose late replies a request
    of ``key`` could mistake for its answer (default: its own).
    """

    def __init__(
        self,
        write: Callable[[P], Awaitable[None]],
        *,
        link: str = "link",
        describe_key: Callable[[K], str] = repr,
        describe_request: Callable[[P], str] = repr,
        trace_request: Callable[[P], object] | None = None,
        retries: int = DEFAULT_RETRIES,
        query_interval_s: float = 0.0,
        late_reply_s: float = DEFAULT_LATE_REPLY_S,
        eeprom_guard: EepromGuard | None = None,
        pull: Callable[[], Awaitable[None]] | None = None,
        flush: Callable[[], None] | None = None,
        owed_keys: Callable[[K], Iterable[K]] | None = None,
    ) -> None:
        self.retries = checks.count("retries", retries)
        self.query_interval_s = checks.non_negative_seconds("query_interval_s",
                                                            query_interval_s)
        #: Replies owed by timed-out attempts (``late``, ``given_up``, ``drains``).
        self.late_replies: LateReplies[K] = LateReplies(
            checks.non_negative_seconds("late_reply_s", late_reply_s), describe_key)
        self.guard = eeprom_guard if eeprom_guard is not None else EepromGuard()
        self.stats = TransactionStats()
        self.link = link
        self._write = write
        self._describe_key = describe_key
        self._describe_request = describe_request
        self._trace_request = trace_request
        self._pull = pull
        self._flush = flush
        self._owed_keys = owed_keys
        self._hooks: list[LinkTraceHook] = []
        #: Any trace hook installed (read only; skip decoding for the trace when False).
        self.tracing = False
        self._lanes: dict[Hashable, asyncio.Lock] = {}
        self._waiting: dict[K, asyncio.Future[V]] = {}  # the attempt waiting per key
        self._deadlines: dict[K, float] = {}  # loop time, set once its request has left
        self._graced: set[K] = set()  # attempts given GRACE_TURNS after a stall
        self._last_query = -1e9  # time.monotonic() when the last request's write returned
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = 0.0
        self._closed = False
        self._dead: ConnectionLost | None = None
        self._on_lost: list[Callable[[ConnectionLost], object]] = []

    def on_lost(self, callback: Callable[[ConnectionLost], object]) -> None:
        """``callback(error)`` once when the medium is lost (closed by the peer, failed) -
        the transport-closed signal the machine reopens links on (issue 29); never for
        :meth:`close`. At once when it already was lost."""
        if self._dead is not None and not self._closed:
            callback(self._dead)
            return
        self._on_lost.append(callback)

    # ------------------------------------------------------------- tracing
    def add_trace(self, hook: LinkTraceHook) -> None:
        """``hook(direction, item, t)``: every request sent, every reply and error met."""
        self._hooks.append(hook)
        self.tracing = True

    def trace(self, direction: Direction, item: object) -> None:
        t = time.monotonic()
        for hook in self._hooks:
            hook(direction, item, t)

    # ------------------------------------------------------------- sending
    def lane(self, lane: Hashable = None) -> asyncio.Lock:
        """The lock of ``lane``: requests of one lane run one at a time."""
        lock = self._lanes.get(lane)
        if lock is None:
            lock = self._lanes[lane] = asyncio.Lock()
        return lock

    def check_alive(self) -> None:
        """ConnectionLost when the link died or the client was closed."""
        if self._dead is not None:
            raise ConnectionLost(str(self._dead))

    def check_eeprom(self, drive_id: int, item: str) -> None:
        """Before sending an EEPROM write of ``item``: the guard may warn or refuse."""
        try:
            self.guard.check(drive_id, item)
        except EepromGuardError as exc:
            log.warning("%s", exc)
            raise

    async def send(self, payload: P) -> None:
        """Hand a command without a reply to the medium: once, never paced or waited on."""
        self.check_alive()
        await self._put(payload)

    async def request(self, key: K, payload: P, *, deadline_s: float, retry_safe: bool,
                      retries: int | None = None, lane: Hashable = None) -> V:
        """Send ``payload`` and return the reply the receive path hands to
        :meth:`answer` for ``key``, by the rules of the module docstring."""
        if self._dead is not None:
            raise ConnectionLost(str(self._dead))
        lock = self._lanes.get(lane)
        if lock is None:
            lock = self.lane(lane)
        # acquire/release rather than ``async with``: two coroutine frames less per call
        # (the attempts run inline for the same reason: this is every transaction's path)
        await lock.acquire()
        try:
            n_retries = (self.retries if retries is None else retries) if retry_safe else 0
            late = self.late_replies
            if late:
                keys = (key,) if self._owed_keys is None else self._owed_keys(key)
                await late.drain(keys, pull=self._pull_checked if self._pull else None)
            last: DriveTimeout | ChecksumError | None = None
            for attempt in range(n_retries + 1):
                if attempt:
                    self.stats.retries += 1
                    if log.isEnabledFor(logging.DEBUG):
                        log.debug("retry %d of %d: %s after %s", attempt, n_retries,
                                  self._describe_request(payload), type(last).__name__)
                if self.query_interval_s > 0:
                    await self._pace()
                if self._pull is not None and late:
                    await self._absorb()
                if self._flush is not None:
                    self._flush()
                try:
                    reply = await self._attempt(key, payload, deadline_s)
                except _Expired:
                    last = self._timed_out(payload, deadline_s)
                    continue
                except ChecksumError as exc:
                    last = exc
                    continue
                self.stats.replies += 1
                return reply
        finally:
            lock.release()
        if isinstance(last, DriveTimeout):
            raise DriveTimeout(f"no reply from {self._describe_request(payload)} after "
                               f"{n_retries + 1} attempt(s) of {deadline_s * 1000:.1f} ms")
        assert last is not None
        raise last

    async def _attempt(self, key: K, payload: P, deadline_s: float) -> V:
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[V] = loop.create_future()
        self._waiting[key] = fut
        sent = False  # the request may have left (a cancelled write may have, too)
        try:
            if self._hooks:
                self.trace(Direction.TX, payload if self._trace_request is None
                           else self._trace_request(payload))
            self.stats.sent += 1
            sent = True
            try:
                await self._write(payload)
            except OSError as exc:
                raise self.lost(exc) from exc
            self._last_query = time.monotonic()  # the bytes have left: the pacing clock
            if not fut.done():  # an in-process medium may have answered during write
                if self._pull is None:
                    self._deadlines[key] = when = loop.time() + deadline_s
                    if self._timer is None or self._timer_at > when:
                        self._arm(loop, when)
                else:
                    await self._pull_until(key, fut, loop.time() + deadline_s)
            return await fut
        except BaseException:
            if fut.done() and not fut.cancelled():
                fut.exception()  # retrieved: asyncio logs no "never retrieved"
            elif sent and self._dead is None:
                # Cancelled by the caller (asyncio.timeout, wait_for, a sync call's
                # timeout, Ctrl-C) after the request left: its reply may still come and
                # must never answer a later call (issue 17.7).
                self.late_replies.owe(key)
            raise
        finally:
            del self._waiting[key]
            if self._deadlines:
                self._deadlines.pop(key, None)
            if self._graced:
                self._graced.discard(key)

    async def _put(self, payload: P) -> None:
        if self._hooks:
            self.trace(Direction.TX, payload if self._trace_request is None
                       else self._trace_request(payload))
        self.stats.sent += 1
        try:
            await self._write(payload)
        except OSError as exc:
            raise self.lost(exc) from exc

    async def _pace(self) -> None:
        """Wait until ``query_interval_s`` has passed since the last request left."""
        while True:
            wait = self._last_query + self.query_interval_s - time.monotonic()
            if wait <= 0:
                return
            await asyncio.sleep(wait)

    def _timed_out(self, payload: P, deadline_s: float) -> DriveTimeout:
        self.stats.timeouts += 1
        exc = DriveTimeout(f"no reply from {self._describe_request(payload)} within "
                           f"{deadline_s * 1000:.1f} ms")
        if self._hooks:
            self.trace(Direction.RX, exc)
        log.debug("%s", exc)
        return exc

    # ------------------------------------------------------------- deadlines
    def _arm(self, loop: asyncio.AbstractEventLoop, when: float) -> None:
        """One timer serves every waiting attempt: set for the earliest deadline, re-armed
        when it fires for the next one. Saves a timer per transaction on the hot path."""
        if self._timer is not None:
            self._timer.cancel()
        self._timer_at = when
        self._timer = loop.call_at(when, self._on_timer, loop)

    def _on_timer(self, loop: asyncio.AbstractEventLoop) -> None:
        self._timer = None
        now = loop.time()
        stalled = now - self._timer_at > STALL_S
        nearest: float | None = None
        for key, when in list(self._deadlines.items()):
            fut = self._waiting[key]
            if fut.done():
                continue
            if when <= now and stalled and key not in self._graced:
                self._graced.add(key)  # module docstring: a stalled host
                del self._deadlines[key]
                loop.call_soon(self._expire_after, GRACE_TURNS, key, fut)
            elif when <= now:
                self._expire(key, fut)
            elif nearest is None or when < nearest:
                nearest = when
        if nearest is not None:
            self._arm(loop, nearest)

    def _expire_after(self, turns: int, key: K, fut: asyncio.Future[V]) -> None:
        """Expire ``fut`` unless answered within ``turns`` more loop turns."""
        if fut.done():
            return
        if turns > 0:
            asyncio.get_running_loop().call_soon(self._expire_after, turns - 1, key, fut)
        else:
            self._expire(key, fut)

    def _expire(self, key: K, fut: asyncio.Future[V]) -> None:
        self.late_replies.owe(key)  # its reply may still come: never to a later call
        fut.set_exception(_Expired())

    # ------------------------------------------------------------- pull media
    async def _pull_checked(self) -> None:
        assert self._pull is not None
        try:
            await self._pull()
        except TimeoutError:
            raise
        except OSError as exc:
            raise self.lost(exc) from exc

    async def _pull_until(self, key: K, fut: asyncio.Future[V], end: float) -> None:
        loop = asyncio.get_running_loop()
        while not fut.done():
            left = end - loop.time()
            if left <= 0:
                self._expire(key, fut)
                return
            try:
                async with asyncio.timeout(left):
                    await self._pull_checked()
            except TimeoutError:
                continue

    async def _absorb(self) -> None:
        """Pull media: frame what is already buffered (owed late replies pay their debt)
        instead of letting ``flush`` drop it unseen. Does not wait for more."""
        while True:
            try:
                async with asyncio.timeout(0):
                    await self._pull_checked()
            except TimeoutError:
                return

    # ------------------------------------------------------------- the receive path
    def answer(self, key: K, reply: V) -> bool:
        """``reply`` arrived for ``key``: True if a request waited for it (it returns it)."""
        fut = self._waiting.get(key)
        if fut is None or fut.done():
            return False
        fut.set_result(reply)
        return True

    def reject(self, exc: BaseException, key: K | None = None) -> bool:
        """Fail the waiting request of ``key`` with ``exc`` (None: every waiting request, e.g.
        a corrupt reply on a line with one request at a time). ChecksumError fails only the
        attempt (a read is retried); any other error ends the call. True if one waited."""
        hit = False
        for k, fut in self._waiting.items():
            if (key is None or k == key) and not fut.done():
                fut.set_exception(exc)
                hit = True
        return hit

    @property
    def awaiting_reply(self) -> bool:
        """A request waits for its reply now."""
        return any(not fut.done() for fut in self._waiting.values())

    def waiting_keys(self) -> list[K]:
        """Keys of the requests waiting for their reply now."""
        return [k for k, fut in self._waiting.items() if not fut.done()]

    def late(self, key: K) -> bool:
        """A reply of ``key`` that no request waits for: True if a timed-out attempt owed
        it (drop it; counted in ``stats.late_replies``), False if it is a stray."""
        if self.late_replies.take(key):
            self.stats.late_replies += 1
            return True
        return False

    def stray(self, item: object) -> None:
        """Something that answers nothing: counted by kind (ChecksumError, another
        ProtocolError = framing, anything else = unmatched) and logged at debug level."""
        if isinstance(item, ChecksumError):
            self.stats.checksum_errors += 1
        elif isinstance(item, ProtocolError):
            self.stats.framing_errors += 1
        else:
            self.stats.unmatched += 1
        log.debug("stray %s", item)

    # ------------------------------------------------------------- the end of the link
    def lost(self, exc: BaseException) -> BaseException:
        """``exc`` met on the medium, as the client raises it: an OSError becomes
        ConnectionLost, which ends every waiting request and every later call at once."""
        out = checks.lost(exc, f"{self.link} lost")
        if isinstance(out, ConnectionLost):
            if self._dead is None:
                self._dead = out
                log.debug("%s", out)
                callbacks, self._on_lost = self._on_lost, []
                for callback in callbacks:
                    callback(out)
            self._hang_up()
        return out

    def _hang_up(self) -> None:
        dead = self._dead
        assert dead is not None
        self.late_replies.hang_up(ConnectionLost(str(dead)))
        for key, fut in self._waiting.items():
            if not fut.done():
                fut.set_exception(ConnectionLost(
                    f"{dead} while waiting for {self._describe_key(key)}"))

    def close(self) -> bool:
        """Mark the client closed (later calls: ConnectionLost; waiting ones fail now).
        False if it already was; the client then closes its medium."""
        if self._closed:
            return False
        self._closed = True
        if self._dead is None:
            self._dead = ConnectionLost("client is closed")
        self._on_lost.clear()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._hang_up()
        return True

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def dead(self) -> ConnectionLost | None:
        """Why the link is unusable (closed or lost), or None while it works."""
        return self._dead
