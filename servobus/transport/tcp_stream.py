"""Raw TCP byte stream on asyncio (serial-to-TCP bridges, ``servobus sim --listen tcp://``).

Used for ``socket://host:port`` URLs instead of pyserial's implementation: no reader thread
and no thread hop per reply, so a round trip costs one event-loop wake-up (see
benchmarks/bench_dyn232_client.py for the measured difference). TCP_NODELAY is set because
every packet is a few bytes and Nagle's algorithm would hold the next request back.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from urllib.parse import urlsplit

from servobus.errors import ServobusError
from servobus.transport.base import Direction, TraceHook


def parse_host_port(url: str) -> tuple[str, int]:
    """``socket://host:port`` or ``tcp://host:port`` -> (host, port)."""
    parts = urlsplit(url)
    if parts.scheme not in ("socket", "tcp") or not parts.hostname or parts.port is None:
        raise ServobusError(f"expected socket://HOST:PORT or tcp://HOST:PORT, got {url!r}")
    return parts.hostname, parts.port


class TcpStream:
    """A connected TCP socket as a :class:`ByteStream`."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._reader = reader
        self._writer = writer
        self._traces: list[TraceHook] = []
        self._closed = False
        sock = writer.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    @classmethod
    async def connect(cls, host: str, port: int, *, timeout: float = 5.0) -> TcpStream:
        try:
            reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port),
                                                    timeout)
        except (OSError, TimeoutError) as exc:
            raise ServobusError(f"cannot connect to {host}:{port}: {exc}") from exc
        return cls(reader, writer)

    @classmethod
    async def open_url(cls, url: str, *, timeout: float = 5.0) -> TcpStream:
        host, port = parse_host_port(url)
        return await cls.connect(host, port, timeout=timeout)

    def add_trace(self, hook: TraceHook) -> None:
        self._traces.append(hook)

    def _trace(self, direction: Direction, data: bytes) -> None:
        t = time.monotonic()
        for hook in self._traces:
            hook(direction, data, t)

    async def write(self, data: bytes) -> None:
        if self._closed or self._writer.is_closing():
            raise ConnectionError("stream is closed")
        if self._traces:
            self._trace(Direction.TX, bytes(data))
        self._writer.write(data)
        if self._writer.transport.get_write_buffer_size() > 65536:
            await self._writer.drain()

    async def read(self, max_bytes: int = 4096) -> bytes:
        if self._closed:
            raise ConnectionError("stream is closed")
        data = await self._reader.read(max_bytes)
        if not data:
            raise ConnectionError("connection closed by peer")
        if self._traces:
            self._trace(Direction.RX, data)
        return data

    def discard_input(self) -> None:
        # StreamReader has no public flush; drop what it buffered (private but stable API).
        buffer = getattr(self._reader, "_buffer", None)
        if isinstance(buffer, bytearray):
            buffer.clear()

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._writer.close()
        with contextlib.suppress(ConnectionError, OSError):
            await self._writer.wait_closed()
