"""ClientAxis: the part of every AsyncAxis that is one drive address on a protocol client.

The client (one serial line, CAN bus or socket) may serve several axes: the first axis owns
it and closes it, ``sibling`` axes share it (and the virtual drives' trace and I/O sources)
without owning it. CommandAxis (DMM) and YzaimAxis (YZ-AIM) build on this.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Awaitable, Callable
from typing import Any, ClassVar, Generic, Protocol, Self, TypeVar

from servobus.axis.base import AsyncAxis, AxisTraceHook
from servobus.axis.capabilities import Capability
from servobus.errors import ConnectionLost
from servobus.link.stats import TransactionStats
from servobus.link.transaction import TransactionManager


class LinkClient(Protocol):
    """What a ClientAxis needs of any protocol client."""

    transactions: TransactionManager[Any, Any, Any]

    def add_trace(self, hook: AxisTraceHook) -> None: ...
    async def close(self) -> None: ...


C = TypeVar("C", bound=LinkClient)


class ClientAxis(AsyncAxis, Generic[C]):
    """One drive address on a (possibly shared) protocol client."""

    protocol_name: ClassVar[str]
    #: How ``repr`` names the address ("id" on DMM drives, "motor" on YZ-AIM).
    address_word: ClassVar[str] = "id"
    #: Every link client counts its transactions.
    protocol_capabilities: ClassVar[frozenset[Capability]] = frozenset({Capability.LINK_STATS})

    def __init__(self, client: C, drive_id: int, *, owns_client: bool = True) -> None:
        self.client = client
        self._id = self._check_id(drive_id)
        self._owns_client = owns_client
        self._closers: list[Callable[[], Awaitable[None]]] = []

    @abstractmethod
    def _check_id(self, drive_id: int) -> int:
        """The drive address, or ArgumentRangeError (before anything is sent)."""

    def on_close(self, closer: Callable[[], Awaitable[None]]) -> None:
        """Run ``closer`` after the client closes (e.g. an in-process virtual drive's task)."""
        self._closers.append(closer)

    @property
    def drive_id(self) -> int:
        return self._id

    @property
    def protocol(self) -> str:
        return self.protocol_name

    async def sibling(self, drive_id: int) -> Self:
        axis = type(self)(self.client, drive_id, owns_client=False)
        axis.capture_source = self.capture_source  # same connection, same drives' traces
        axis.io_source = self.io_source  # and the same virtual I/O
        return axis

    async def add_trace(self, hook: AxisTraceHook) -> None:
        self.client.add_trace(hook)

    def link_stats(self) -> TransactionStats:
        return self.client.transactions.stats

    def on_link_lost(self, callback: Callable[[ConnectionLost], object]) -> bool:
        """The client's transaction manager hears of the medium's end (link.transaction)."""
        self.client.transactions.on_lost(callback)
        return True

    async def close(self) -> None:
        if self._owns_client:
            await self.client.close()
            closers, self._closers = self._closers, []
            for closer in closers:
                await closer()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.address_word} {self._id}>"
