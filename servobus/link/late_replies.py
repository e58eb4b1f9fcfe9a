"""Replies still owed by requests that timed out, so that a late one never answers a later call.

DYN232M replies carry the answering drive's id and the reply function only (DYN2 manual
7.2), DYN CAN replies their 11-bit identifier only (drive id, function code): neither has a
sequence number. A read that timed out may still be answered (a USB-serial latency timer,
a serial-to-TCP bridge, a loaded host); that reply would match the next read of the same
kind and hand it a value older than its own call.

Rules (servobus decisions; docs/dyn232.md and docs/dyncan.md, "late replies"):

* Each attempt that times out owes one reply, under the key a reply is matched on
  (drive id, reply function), and so does an attempt its caller cancelled after the
  request left (``asyncio.timeout``, ``wait_for``, a sync call's timeout, Ctrl-C: before
  issue 17.7 it owed nothing, and its late reply answered the next read of its kind - the
  stale position after a move). A cancel just before the bytes left still owes: the debt
  is then given up after ``late_reply_s`` (a wait, never a wrong value). Replies arrive in
  request order on one line or identifier.
* A reply that arrives while a request of its key waits is that request's answer (within
  one call every request is younger than the call). Any other reply of an owed key pays
  one debt and is dropped (``late``, logged at debug level).
* Before the first attempt of a read whose key is owed, the client drains: it sends nothing
  until every owed reply of that key has come, or none of them for ``late_reply_s`` (quiet
  time, restarted by each late reply). The rest is then given up (``given_up``): lost, not
  late. Reads of other keys never wait (their replies cannot be mistaken).
* Bound of the guarantee: a reply later than ``late_reply_s`` after the last sign of its key
  cannot be told from an answer. ``late_reply_s=0`` turns the drain off (old behaviour).

Cost: only after a timeout, only for the next read of the same kind, at most
``late_reply_s`` per lost reply when the reply never comes (a real drive that dropped a
query). Nothing changes on the fast path.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable, Hashable, Iterable
from dataclasses import dataclass
from typing import Generic, TypeVar

log = logging.getLogger(__name__)

K = TypeVar("K", bound=Hashable)

#: Default quiet time (servobus decision): covers USB-serial latency timers (16 ms on FTDI),
#: serial-to-TCP bridges and a loaded host, about 7 x the 38400-baud reply deadline.
DEFAULT_LATE_REPLY_S = 0.2


@dataclass
class _Debt:
    count: int
    quiet_until: float  # loop time: give the rest up when nothing came by then


class LateReplies(Generic[K]):
    """Owed replies per key, with a drain that waits on arrivals (loop thread only)."""

    def __init__(self, late_reply_s: float, describe: Callable[[K], str] = repr) -> None:
        self.late_reply_s = late_reply_s
        self.late = 0  # replies dropped because they were owed to timed-out requests
        self.given_up = 0  # owed replies that never came within the quiet time
        self.drains = 0  # reads that waited for owed replies before sending
        self._debts: dict[K, _Debt] = {}
        self._latest = 0.0  # the latest quiet_until of any debt: past it, all are given up
        self._waiters: list[asyncio.Future[None]] = []
        self._describe = describe

    def __bool__(self) -> bool:
        """Any debt still open. Once every quiet time has passed all are given up, so a
        timeout long ago costs the receive path nothing (scans leave many keys owed)."""
        if not self._debts:
            return False
        if time.monotonic() > self._latest:
            for key, debt in list(self._debts.items()):
                self._give_up(key, debt)
            return False
        return True

    def owe(self, key: K) -> None:
        """An attempt for ``key`` timed out: its reply may still come."""
        if self.late_reply_s <= 0:
            return
        now = time.monotonic()
        until = now + self.late_reply_s
        self._latest = max(self._latest, until)
        debt = self._debts.get(key)
        if debt is None:
            self._debts[key] = _Debt(1, until)
        else:
            debt.count += 1
            debt.quiet_until = max(debt.quiet_until, until)

    def take(self, key: K) -> bool:
        """A reply of ``key`` arrived and no request of its key waits: True if it was owed
        (the caller drops it), False if nothing was owed (a stray) or the debt expired."""
        debt = self._debts.get(key)
        if debt is None:
            return False
        now = time.monotonic()
        if now > debt.quiet_until:
            self._give_up(key, debt)
            return False
        self.late += 1
        debt.count -= 1
        log.debug("late reply %s dropped (%d more owed)", self._describe(key), debt.count)
        if debt.count <= 0:
            del self._debts[key]
        else:
            debt.quiet_until = now + self.late_reply_s
            self._latest = max(self._latest, debt.quiet_until)
        self._wake(None)
        return True

    def owed(self, key: K) -> bool:
        return key in self._debts

    def keys(self, wanted: Callable[[K], bool]) -> list[K]:
        return [k for k in self._debts if wanted(k)]

    def wait_s(self, keys: Iterable[K]) -> float:
        """Seconds a drain of ``keys`` must still wait (0: settled; expired debts given up)."""
        now = time.monotonic()
        longest = 0.0
        for key in list(keys):
            debt = self._debts.get(key)
            if debt is None:
                continue
            left = debt.quiet_until - now
            if left <= 0:
                self._give_up(key, debt)
            else:
                longest = max(longest, left)
        return longest

    def _give_up(self, key: K, debt: _Debt) -> None:
        del self._debts[key]
        self.given_up += debt.count
        log.debug("gave up %d owed reply(ies) %s after %.0f ms without one",
                  debt.count, self._describe(key), self.late_reply_s * 1000)

    async def drain(self, keys: Iterable[K],
                    pull: Callable[[], Awaitable[None]] | None = None) -> None:
        """Wait until the debts of ``keys`` are paid or given up. The client's receive path
        calls :meth:`take` for each reply; media that push call it themselves (then
        :meth:`hang_up` ends the wait at once); for media that can only be read, ``pull``
        reads once and feeds the receive path (an error it raises ends the drain)."""
        wanted = list(keys)
        loop = asyncio.get_running_loop()
        left = self.wait_s(wanted)
        if left <= 0:
            return
        self.drains += 1
        log.debug("waiting up to %.0f ms for late replies %s before sending", left * 1000,
                  ", ".join(self._describe(k) for k in wanted if k in self._debts))
        while left > 0:
            if pull is not None:
                try:
                    async with asyncio.timeout(left):
                        await pull()
                except TimeoutError:
                    pass
                left = self.wait_s(wanted)
                continue
            fut: asyncio.Future[None] = loop.create_future()
            self._waiters.append(fut)
            timer = loop.call_later(left, _resolve, fut)
            try:
                await fut
            finally:
                timer.cancel()
                if fut in self._waiters:
                    self._waiters.remove(fut)
            left = self.wait_s(wanted)

    def hang_up(self, exc: BaseException) -> None:
        """The medium is gone: a drain in progress fails with ``exc`` at once."""
        self._wake(exc)

    def _wake(self, exc: BaseException | None) -> None:
        waiters, self._waiters = self._waiters, []
        for fut in waiters:
            if fut.done():
                continue
            if exc is None:
                fut.set_result(None)
            else:
                fut.set_exception(exc)


def _resolve(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)
