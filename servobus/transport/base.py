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

#: Push-style reception (optional, see :class:`PushByteStream`): each received chunk, on the
#: loop thread, after the RX trace hooks; then ``None`` once when the stream closes or fails.
ByteReceiver = Callable[["bytes | None"], None]


@runtime_checkable
class ByteStream(Protocol):
    """An ordered, lossy-as-the-wire byte stream. All methods run on one event loop."""

    async def write(self, data: bytes) -> None:
        """Queue ``data`` for sending; returns once it is handed to the medium."""

    async def read(self, max_bytes: int = 4096) -> bytes:
        """Wait for at least one byte; return what is available (up to ``max_bytes``).

        Raises :class:`~servobus.errors.ConnectionLost` (a ``ConnectionError``) when the
        stream is closed or the medium failed; ``write`` does the same.
        """

    def discard_input(self) -> None:
        """Drop bytes received but not yet read (resynchronisation after a timeout)."""

    async def close(self) -> None:
        """Release the medium; idempotent."""

    def add_trace(self, hook: TraceHook) -> None:
        """Call ``hook`` for every chunk written (TX) or received (RX)."""


@runtime_checkable
class PushByteStream(ByteStream, Protocol):
    """A ByteStream that can also push received bytes to a callback (optional capability).

    A client that waits for replies saves a task switch and a buffer copy per reply: the
    transport's receive callback hands the bytes straight to the client's framer. Streams
    without it (pyserial, the fault-injecting pair) are read with ``read()``.
    """

    def set_receiver(self, receiver: ByteReceiver | None) -> None:
        """Push every chunk received from now on to ``receiver`` instead of buffering it for
        ``read()`` (``None`` reverts to ``read()``). Bytes buffered before are kept for
        ``read()``/``discard_input()``. When the stream closes or fails, ``receiver(None)``
        is called once."""


def set_receiver(stream: ByteStream, receiver: ByteReceiver | None) -> bool:
    """Install ``receiver`` on ``stream`` if it supports push reception; True if it does."""
    method = getattr(stream, "set_receiver", None)
    if method is None:
        return False
    method(receiver)
    return True
