"""A virtual CAN bus served over the socketcand protocol (rawmode), plus in-process ports.

python-can's ``interface="socketcand"`` connects from another process
(``can="socketcand:127.0.0.1:PORT"``). Protocol subset, as python-can's client speaks it
(can/interfaces/socketcand/socketcand.py) and socketcand documents it:

    server: < hi >                       on connect
    client: < open CHANNEL >   server: < ok >      any channel name is accepted
    client: < rawmode >        server: < ok >
    client: < send 03A 2 1 ff >                    id hex, dlc hex, data bytes hex
    server: < frame 03A 1712345678.123456 01FF >   id hex (3 digits = 11-bit, 8 = 29-bit),
                                                   seconds.microseconds, data hex

Decisions: a frame goes to every other endpoint (TCP clients in rawmode, in-process ports),
never back to its sender, like a CAN controller that does not receive its own frames. A
client starts receiving 20 ms after its rawmode ``< ok >``: python-can's handshake reads
with a single recv() and would fail if a frame were glued to that ``< ok >``. ``< echo >``
is answered; other commands get ``< error unsupported >``. Binds 127.0.0.1 by default.
"""

from __future__ import annotations

import asyncio
import contextlib
import time

from servobus.errors import ArgumentRangeError
from servobus.transport.base import Direction
from servobus.transport.can_bus import BitTiming, BusPacer, CanFrame, FrameTraceHook

RAWMODE_SETTLE_S = 0.020
MAX_MESSAGE = 256  # a socketcand message is far shorter; longer input is garbage


def format_frame(frame: CanFrame) -> str:
    ident = (f"{frame.arbitration_id:08X}" if frame.is_extended_id
             else f"{frame.arbitration_id:03X}")
    sec = int(frame.timestamp)
    usec = round((frame.timestamp - sec) * 1e6) % 1_000_000
    return f"< frame {ident} {sec}.{usec:06d} {frame.data.hex().upper()} >"


def parse_send(tokens: list[str]) -> CanFrame:
    """``send ID DLC B0 B1 ...`` (tokens without the angle brackets)."""
    if len(tokens) < 3:
        raise ValueError("send needs an id and a dlc")
    ident_text, dlc = tokens[1], int(tokens[2], 16)
    data = bytes(int(b, 16) for b in tokens[3:3 + dlc])
    if not 0 <= dlc <= 8 or len(data) != dlc:
        raise ValueError(f"dlc {dlc} does not match {len(data)} data byte(s)")
    extended = len(ident_text) > 3
    ident = int(ident_text, 16)
    if ident > (0x1FFFFFFF if extended else 0x7FF):
        raise ValueError(f"identifier {ident_text} out of range")
    return CanFrame(ident, data, time.time(), extended)


class HubPort:
    """An in-process endpoint on the hub (a :class:`FramePort`)."""

    def __init__(self, hub: SocketcandHub, timing: BitTiming | None = None) -> None:
        self._hub = hub
        self._queue: asyncio.Queue[CanFrame | None] = asyncio.Queue()
        self._traces: list[FrameTraceHook] = []
        self._closed = False
        self.pacer = BusPacer(timing) if timing is not None else None

    def deliver(self, frame: CanFrame) -> None:
        if self._closed:
            return
        now = time.monotonic()
        if self.pacer is not None:
            self.pacer.occupy(len(frame.data), now)
        for hook in self._traces:
            hook(Direction.RX, frame, now)
        self._queue.put_nowait(frame)

    async def send(self, arbitration_id: int, data: bytes) -> None:
        if self._closed:
            raise ConnectionError("hub port is closed")
        if self.pacer is not None:
            await self.pacer.wait_sent(len(data))
        frame = CanFrame(arbitration_id, bytes(data), time.time())
        for hook in self._traces:
            hook(Direction.TX, frame, time.monotonic())
        self._hub.publish(frame, self)

    async def recv(self, timeout: float | None = None) -> CanFrame | None:
        if self._closed and self._queue.empty():
            raise ConnectionError("hub port is closed")
        try:
            item = self._queue.get_nowait()
        except asyncio.QueueEmpty:
            try:
                item = await asyncio.wait_for(self._queue.get(), timeout)
            except TimeoutError:
                return None
        if item is None:
            raise ConnectionError("hub port is closed")
        return item

    def add_trace(self, hook: FrameTraceHook) -> None:
        self._traces.append(hook)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._queue.put_nowait(None)
            self._hub.detach(self)


class _Session:
    """One TCP client."""

    def __init__(self, hub: SocketcandHub, writer: asyncio.StreamWriter) -> None:
        self.hub = hub
        self.writer = writer
        self.receiving = False

    def deliver(self, frame: CanFrame) -> None:
        if self.receiving and not self.writer.is_closing():
            self.writer.write(format_frame(frame).encode("ascii"))

    def reply(self, text: str) -> None:
        self.writer.write(text.encode("ascii"))

    async def run(self, reader: asyncio.StreamReader) -> None:
        self.reply("< hi >")
        buf = b""
        while True:
            chunk = await reader.read(4096)
            if not chunk:
                return
            buf += chunk
            while True:
                start, end = buf.find(b"<"), buf.find(b">")
                if start < 0:
                    buf = b""
                    break
                if end < 0:
                    buf = buf[start:] if len(buf) - start < MAX_MESSAGE else b""
                    break
                if end < start:
                    buf = buf[start:]
                    continue
                message, buf = buf[start + 1:end], buf[end + 1:]
                await self._command(message.decode("ascii", "replace").split())

    async def _command(self, tokens: list[str]) -> None:
        if not tokens:
            return
        word = tokens[0]
        if word == "open":
            self.reply("< ok >")
        elif word == "rawmode":
            self.reply("< ok >")
            await self.writer.drain()
            await asyncio.sleep(RAWMODE_SETTLE_S)
            self.receiving = True
        elif word == "send":
            try:
                frame = parse_send(tokens)
            except ValueError as exc:
                self.reply(f"< error {exc} >")
                return
            self.hub.frames_from_tcp += 1
            self.hub.publish(frame, self)
        elif word == "echo":
            self.reply("< echo >")
        else:
            self.reply("< error unsupported >")


Endpoint = HubPort | _Session


class SocketcandHub:
    """The virtual bus: TCP sessions and in-process ports; every frame reaches all others."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self.host = host
        self.port = port
        self._endpoints: list[Endpoint] = []
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self.frames_from_tcp = 0

    async def start(self) -> tuple[str, int]:
        self._server = await asyncio.start_server(self._on_client, self.host, self.port)
        sock = self._server.sockets[0]
        self.host, self.port = sock.getsockname()[:2]
        return self.host, self.port

    def open_port(self, timing: BitTiming | None = None) -> HubPort:
        port = HubPort(self, timing)
        self._endpoints.append(port)
        return port

    def detach(self, endpoint: Endpoint) -> None:
        with contextlib.suppress(ValueError):
            self._endpoints.remove(endpoint)

    def publish(self, frame: CanFrame, sender: Endpoint) -> None:
        for endpoint in self._endpoints:
            if endpoint is not sender:
                endpoint.deliver(frame)

    async def _on_client(self, reader: asyncio.StreamReader,
                         writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._tasks.add(task)
        sock = writer.get_extra_info("socket")
        if sock is not None:
            import socket

            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        session = _Session(self, writer)
        self._endpoints.append(session)
        try:
            await session.run(reader)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self.detach(session)
            writer.close()
            with contextlib.suppress(ConnectionError, OSError):
                await writer.wait_closed()
            if task is not None:
                self._tasks.discard(task)

    @property
    def clients(self) -> int:
        return sum(isinstance(e, _Session) for e in self._endpoints)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._tasks):
            task.cancel()
        for task in list(self._tasks):
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if self._server is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 1.0)
        for endpoint in list(self._endpoints):
            if isinstance(endpoint, HubPort):
                await endpoint.close()


def parse_socketcand_address(text: str) -> tuple[str, int]:
    """"HOST:PORT" -> (host, port); PORT 0 picks a free port."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ArgumentRangeError(f"socketcand address {text!r} must be HOST:PORT")
    return host or "127.0.0.1", int(port)
