"""The byte-stream interface every serial-like transport implements (asyncio).

Implementations: pyserial ports and URLs, TCP, the in-process virtual line (``sim://``),
and the fault-injecting in-process pair. Clients only ever see this interface.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum
from typing import Protocol, runtime_checkable


class Direction(Enum):
    TX = "tx"  # host -> drive
    RX = "rx"  # drive -> host


#: Called with every chunk of bytes moved, and the monotonic time it moved.
TraceHook = Callable[[Direction, bytes, float], None]


@runtime_checkable
class ByteStream(Protocol):
    """An ordered, lossy-as-the-wire byte stream. All methods run on one event loop."""

    async def write(self, data: bytes) -> None:
        """Queue ``data`` for sending; returns once it is handed to the medium."""

    async def read(self, max_bytes: int = 4096) -> bytes:
        """Wait for at least one byte; return what is available (up to ``max_bytes``).

        Raises ``ConnectionError`` when the stream is closed.
        """

    def discard_input(self) -> None:
        """Drop bytes received but not yet read (resynchronisation after a timeout)."""

    async def close(self) -> None:
        """Release the medium; idempotent."""

    def add_trace(self, hook: TraceHook) -> None:
        """Call ``hook`` for every chunk written (TX) or received (RX)."""
