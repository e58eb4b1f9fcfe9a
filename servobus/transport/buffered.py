"""Receive-side bookkeeping shared by the byte streams that buffer input for ``read()``.

The fault-injecting pair, pyserial ports and the in-process ``sim://`` line all get their
input as callbacks on the loop thread. :class:`BufferedInput` is the one implementation of
what follows from that: the input buffer and its ready event (``read()``,
``discard_input()``), the closed flag and a medium failure (a pending ``read()`` raises
:class:`~servobus.errors.ConnectionLost` at once), and the fan-out to trace hooks.
:class:`PushInput` adds the optional push capability (``set_receiver``, see
``transport.base.PushByteStream``); streams that do not offer it (pyserial, the pull-only
pair) derive from :class:`BufferedInput` alone, so ``transport.base.set_receiver`` sees that
they have none.

Subclasses call :meth:`_received` for every chunk that arrives, :meth:`_fail` when the
medium breaks and :meth:`_mark_closed` from their ``close()``; they implement ``write()``
and ``close()`` themselves.
"""

from __future__ import annotations

import asyncio
import time

from servobus.errors import ConnectionLost
from servobus.transport.base import ByteReceiver, Direction, TraceHook


class BufferedInput:
    """Input buffer + ready event + closed flag + trace fan-out (+ receiver slot)."""

    #: ``ConnectionLost`` text of a read on a closed stream / after a medium failure.
    closed_text = "stream is closed"
    failed_text = "stream failed"

    def __init__(self) -> None:
        self._buf = bytearray()
        self._ready = asyncio.Event()
        self._closed = False
        self._failure: BaseException | None = None
        self._traces: list[TraceHook] = []
        self._receiver: ByteReceiver | None = None  # only PushInput installs one
        self._hung_up = False

    # ------------------------------------------------------------- traces
    def add_trace(self, hook: TraceHook) -> None:
        self._traces.append(hook)

    def _trace(self, direction: Direction, data: bytes) -> None:
        if self._traces:
            t = time.monotonic()
            for hook in self._traces:
                hook(direction, data, t)

    # ------------------------------------------------------------- input
    def _received(self, data: bytes, direction: Direction = Direction.RX) -> None:
        """Bytes arrived (loop thread): traced, then pushed to the receiver or buffered."""
        traces = self._traces
        if traces:
            t = time.monotonic()
            for hook in traces:
                hook(direction, data, t)
        receiver = self._receiver
        if receiver is not None:
            receiver(data)
            return
        self._buf += data
        self._ready.set()

    def _before_wait(self) -> None:
        """Called each time ``read()`` is about to wait (the sim line starts its runner)."""

    async def read(self, max_bytes: int = 4096) -> bytes:
        buf = self._buf
        while not buf:
            if self._closed:
                raise ConnectionLost(self.closed_text)
            if self._failure is not None:
                raise ConnectionLost(f"{self.failed_text}: {self._failure}")
            self._ready.clear()
            self._before_wait()
            await self._ready.wait()
        out = bytes(buf[:max_bytes])
        del buf[:max_bytes]
        return out

    def discard_input(self) -> None:
        self._buf.clear()

    # ------------------------------------------------------------- end of the stream
    def _fail(self, error: BaseException) -> None:
        """The medium broke: once the buffer is drained, ``read()`` raises ConnectionLost."""
        self._failure = error
        self._ready.set()
        self._hang_up()

    def _mark_closed(self) -> bool:
        """Mark closed, wake a pending ``read()``, tell the receiver; False if already closed."""
        if self._closed:
            return False
        self._closed = True
        self._ready.set()
        self._hang_up()
        return True

    def _hang_up(self) -> None:
        receiver = self._receiver
        if receiver is not None and not self._hung_up:
            self._hung_up = True
            receiver(None)

    @property
    def closed(self) -> bool:
        return self._closed


class PushInput(BufferedInput):
    """:class:`BufferedInput` that can also push received chunks (``PushByteStream``)."""

    def set_receiver(self, receiver: ByteReceiver | None) -> None:
        """Push chunks received from now on to ``receiver`` (``None``: back to ``read()``)."""
        self._receiver = receiver
