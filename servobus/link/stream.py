"""What the byte-stream clients share (DYN232M and Modbus RTU): a client base that owns the
stream, its transaction manager, the receive path's plumbing and closing.

Like :class:`servobus.link.can.CanClient` for the CAN clients: the generic part runs once -
bytes pushed by the stream (TCP, ``sim://``: ``transport.base.PushByteStream``) or pulled by
the manager where the stream can only ``read()`` (pyserial, the pull-only pair), stale input
dropped before each attempt, a dead stream failing every waiting request, closing - and each
protocol supplies two hooks: :meth:`StreamClient._on_bytes` for a chunk that arrived and
:meth:`StreamClient._reset_receiver` for what its framer must forget before an attempt.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Hashable
from typing import Generic, TypeVar

from servobus.errors import ConnectionLost
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import DEFAULT_LATE_REPLY_S, LateReplies
from servobus.link.stats import TransactionStats
from servobus.link.transaction import DEFAULT_RETRIES, LinkTraceHook, TransactionManager
from servobus.transport.base import ByteStream, set_receiver

K = TypeVar("K", bound=Hashable)  # what a reply is matched on
P = TypeVar("P")  # a request as the line takes it
V = TypeVar("V")  # a reply as the receive path hands it over


class StreamClient(ABC, Generic[K, P, V]):
    """Base of a client on one ByteStream (one line, any number of drives): one lane.

    A subclass sets up its receive state, then calls ``super().__init__`` with what its
    transaction manager needs (bytes may arrive from then on), and implements the hooks.
    """

    def __init__(self, stream: ByteStream, write: Callable[[P], Awaitable[None]], *,
                 link: str, describe_key: Callable[[K], str],
                 describe_request: Callable[[P], str],
                 trace_request: Callable[[P], object] | None = None,
                 retries: int = DEFAULT_RETRIES, query_interval_s: float = 0.0,
                 late_reply_s: float = DEFAULT_LATE_REPLY_S,
                 eeprom_guard: EepromGuard | None = None) -> None:
        self.stream = stream
        self._push = set_receiver(stream, self._on_data)
        #: The line's transaction manager (``stats``, ``late_replies`` and ``guard`` are its).
        self.transactions: TransactionManager[K, P, V] = TransactionManager(
            write, link=link, describe_key=describe_key, describe_request=describe_request,
            trace_request=trace_request, retries=retries, query_interval_s=query_interval_s,
            late_reply_s=late_reply_s, eeprom_guard=eeprom_guard,
            pull=None if self._push else self._pull_once, flush=self._flush)
        self.stats: TransactionStats = self.transactions.stats
        #: Replies owed by timed-out attempts (``late_replies.late``, ``.given_up``).
        self.late_replies: LateReplies[K] = self.transactions.late_replies
        self.guard: EepromGuard = self.transactions.guard

    @property
    def retries(self) -> int:
        """Default re-sends of a read (per call: ``retries=``)."""
        return self.transactions.retries

    def add_trace(self, hook: LinkTraceHook) -> None:
        """``hook(direction, item, t)``: every frame sent/received (decoded) and every error."""
        self.transactions.add_trace(hook)

    # ------------------------------------------------------------- the protocol's hooks
    @abstractmethod
    def _on_bytes(self, data: bytes) -> None:
        """A chunk of bytes arrived: an answer, an owed late reply, or strays."""

    @abstractmethod
    def _reset_receiver(self) -> None:
        """Before each attempt: forget partial frames (stale bytes must not answer it)."""

    # ------------------------------------------------------------- receiving
    def _on_data(self, data: bytes | None) -> None:
        """Receive callback (push streams call it; pull streams through ``_pull_once``).
        ``None``: the stream closed or failed, every waiting request fails now."""
        if data is None:
            self.transactions.lost(ConnectionLost("stream closed"))
            return
        self._on_bytes(data)

    async def _pull_once(self) -> None:
        """Pull streams: one ``read()`` through the receive callback."""
        self._on_data(await self.stream.read())

    def _flush(self) -> None:
        """Before each attempt: a push stream buffers nothing (the receive path drops what
        comes between transactions); a pull stream's buffer is discarded."""
        if not self._push:
            self.stream.discard_input()
        self._reset_receiver()

    # ------------------------------------------------------------- closing
    async def close(self) -> None:
        if self.transactions.close():
            await self.stream.close()

    @property
    def closed(self) -> bool:
        return self.transactions.closed
