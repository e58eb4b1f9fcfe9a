"""What the CAN clients share (DYN CAN and EasyCan): a client base that owns the bus, its
receive loop and closing (the python-can channel a drive URL names:
:func:`servobus.axis.url.can_spec`).

Like python-can's ``BusABC.recv`` calling ``_recv_internal``, :class:`CanClient` runs the
generic part once - frames pushed by the port (or read in a loop where the port cannot
push), a dead bus failing every waiting request, closing in order - and each protocol
supplies one hook, :meth:`CanClient._on_can_frame`, for a frame that arrived.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Hashable
from typing import Generic, TypeVar

from servobus.errors import ConnectionLost
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.late_replies import LateReplies
from servobus.link.stats import TransactionStats
from servobus.link.transaction import LinkTraceHook, TransactionManager
from servobus.transport.can_bus import CanFrame, FramePort, set_receiver

K = TypeVar("K", bound=Hashable)  # what a reply is matched on
P = TypeVar("P")  # a request as the bus takes it
V = TypeVar("V")  # a reply as the receive path hands it over


class CanClient(Generic[K, P, V]):
    """Base of a CAN client: one bus (any FramePort) and its transaction manager.

    A subclass builds its :class:`TransactionManager` and calls ``super().__init__`` last
    (frames may arrive from then on), and implements :meth:`_on_can_frame`.
    """

    def __init__(self, port: FramePort, transactions: TransactionManager[K, P, V], *,
                 name: str) -> None:
        self.port = port
        #: The bus's transaction manager (``stats``, ``late_replies`` and ``guard`` are its).
        self.transactions = transactions
        self.stats: TransactionStats = transactions.stats
        #: Replies owed by timed-out attempts (``late_replies.late``, ``.given_up``).
        self.late_replies: LateReplies[K] = transactions.late_replies
        self.guard: EepromGuard = transactions.guard
        self._rx_task: asyncio.Task[None] | None = None
        if not set_receiver(port, self._on_frame):  # push: one task switch less per reply
            self._rx_task = asyncio.get_running_loop().create_task(self._receive_loop(),
                                                                   name=name)

    @property
    def retries(self) -> int:
        """Default re-sends of a read (per call: ``execute(..., retries=)``)."""
        return self.transactions.retries

    def add_trace(self, hook: LinkTraceHook) -> None:
        """``hook(direction, item, t)``: every message sent/received and every error met."""
        self.transactions.add_trace(hook)

    # ------------------------------------------------------------- receiving
    async def _receive_loop(self) -> None:
        while True:
            try:
                raw = await self.port.recv(None)
            except OSError as exc:  # ConnectionLost, or a foreign port's own error
                self.transactions.lost(exc)
                self._on_frame(None)
                return
            if raw is not None:
                self._on_frame(raw)

    def _on_frame(self, raw: CanFrame | None) -> None:
        if raw is None:  # the port closed or failed: every waiting request fails now
            self.transactions.lost(ConnectionLost("CAN bus closed"))
            return
        self._on_can_frame(raw)

    def _on_can_frame(self, raw: CanFrame) -> None:
        """A frame arrived on the bus (the protocol's receive path)."""
        raise NotImplementedError

    # ------------------------------------------------------------- closing
    async def close(self) -> None:
        if not self.transactions.close():
            return
        await self.port.close()
        if self._rx_task is not None:
            self._rx_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._rx_task

    @property
    def closed(self) -> bool:
        return self.transactions.closed
