"""Raw TCP byte stream on asyncio (serial-to-TCP bridges, ``servobus sim --listen tcp://``).

Used for ``socket://host:port`` URLs instead of pyserial's implementation: no reader thread
and no thread hop per reply. Built on an :class:`asyncio.Protocol` (no StreamReader): with a
receiver installed (:meth:`TcpStream.set_receiver`) the bytes go from ``data_received``
straight to the client, so a round trip costs one event-loop wake-up and no extra task step
(see benchmarks/bench_dyn232_client.py). TCP_NODELAY is set because every packet is a few
bytes and Nagle's algorithm would hold the next request back.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from typing import cast
from urllib.parse import urlsplit

from servobus.errors import ConnectionLost, ServobusError
from servobus.transport.base import ByteReceiver, Direction, TraceHook

WRITE_HIGH_WATER = 65536  # wait for the socket to drain above this many queued bytes


def parse_host_port(url: str) -> tuple[str, int]:
    """``socket://host:port`` or ``tcp://host:port`` -> (host, port)."""
    parts = urlsplit(url)
    if parts.scheme not in ("socket", "tcp") or not parts.hostname or parts.port is None:
        raise ServobusError(f"expected socket://HOST:PORT or tcp://HOST:PORT, got {url!r}")
    return parts.hostname, parts.port


class _Protocol(asyncio.Protocol):
    """Receive side of one connection; everything runs on the loop thread."""

    def __init__(self) -> None:
        self.transport: asyncio.Transport | None = None
        self.buf = bytearray()
        self.traces: list[TraceHook] = []
        self.receiver: ByteReceiver | None = None
        self.lost = False
        self.error: BaseException | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._drained: asyncio.Future[None] | None = None
        self.closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # a cast, not an isinstance check: uvloop's transports do not derive from asyncio's
        self.transport = cast(asyncio.Transport, transport)

    def data_received(self, data: bytes) -> None:
        if self.traces:
            t = time.monotonic()
            for hook in self.traces:
                hook(Direction.RX, data, t)
        receiver = self.receiver
        if receiver is not None:
            receiver(data)
            return
        self.buf += data
        self._wake()

    def eof_received(self) -> bool | None:
        return None  # close our side too: a serial bridge has no half-open state

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = True
        self.error = exc
        self._wake()
        if not self.closed.done():
            self.closed.set_result(None)
        drained, self._drained = self._drained, None
        if drained is not None and not drained.done():
            drained.set_result(None)
        if self.receiver is not None:
            self.receiver(None)

    def pause_writing(self) -> None:
        if self._drained is None:
            self._drained = asyncio.get_running_loop().create_future()

    def resume_writing(self) -> None:
        drained, self._drained = self._drained, None
        if drained is not None and not drained.done():
            drained.set_result(None)

    async def drain(self) -> None:
        if self._drained is not None:
            await self._drained

    async def wait_data(self) -> None:
        fut = asyncio.get_running_loop().create_future()
        self._waiter = fut
        try:
            await fut
        finally:
            if self._waiter is fut:
                self._waiter = None

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)


class TcpStream:
    """A connected TCP socket as a :class:`ByteStream` (and a ``PushByteStream``)."""

    def __init__(self, transport: asyncio.Transport, protocol: _Protocol) -> None:
        self._transport = transport
        self._protocol = protocol
        self._closed = False
        sock = transport.get_extra_info("socket")
        if sock is not None and not protocol.lost:
            # a peer that accepts and hangs up at once (a DYN5 rebooting after Reset) may
            # close the socket before this runs: EBADF here; read/write then say
            # ConnectionLost, the typed error a caller retries on
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    @classmethod
    async def connect(cls, host: str, port: int, *, timeout: float = 5.0) -> TcpStream:
        loop = asyncio.get_running_loop()
        try:
            transport, protocol = await asyncio.wait_for(
                loop.create_connection(_Protocol, host, port), timeout)
        except (OSError, TimeoutError) as exc:
            raise ConnectionLost(f"cannot connect to {host}:{port}: {exc}") from exc
        return cls(transport, protocol)

    @classmethod
    async def open_url(cls, url: str, *, timeout: float = 5.0) -> TcpStream:
        host, port = parse_host_port(url)
        return await cls.connect(host, port, timeout=timeout)

    def add_trace(self, hook: TraceHook) -> None:
        self._protocol.traces.append(hook)

    def set_receiver(self, receiver: ByteReceiver | None) -> None:
        self._protocol.receiver = receiver

    def _lost_text(self) -> str:
        error = self._protocol.error
        return "connection closed by peer" if error is None else f"connection lost: {error}"

    async def write(self, data: bytes) -> None:
        protocol = self._protocol
        if self._closed:
            raise ConnectionLost("stream is closed")
        if protocol.lost:
            raise ConnectionLost(self._lost_text())
        if protocol.traces:
            t = time.monotonic()
            chunk = bytes(data)
            for hook in protocol.traces:
                hook(Direction.TX, chunk, t)
        self._transport.write(data)
        if self._transport.get_write_buffer_size() > WRITE_HIGH_WATER:
            await protocol.drain()

    async def read(self, max_bytes: int = 4096) -> bytes:
        protocol = self._protocol
        buf = protocol.buf
        while True:
            if self._closed:
                raise ConnectionLost("stream is closed")
            if buf:
                break
            if protocol.lost:
                raise ConnectionLost(self._lost_text())
            await protocol.wait_data()
        out = bytes(buf[:max_bytes])
        del buf[:max_bytes]
        return out

    def discard_input(self) -> None:
        self._protocol.buf.clear()

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._protocol._wake()  # a pending read() raises ConnectionLost
        self._transport.close()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(asyncio.shield(self._protocol.closed), 2.0)
