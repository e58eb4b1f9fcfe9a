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
never back to its sender, like a CAN controller that does not receive its own frames.
A client's frame is stamped when its TCP data reaches the hub (``timestamp`` wall clock,
``arrived`` monotonic), every frame of one TCP read with the same instant: frames a client
writes at once reach the bus together, whenever the hub's event loop gets round to parsing
them, so a node judges them by that instant (EasyCan's 2 ms cache cycle) and not by the
simulator's load; a shared instant also tells a node that frames came in one read, whose
own arrival times are unknown (a loaded hub reads several cycles' frames at once: the
EasyCan motor queues such cache frames one per cycle, servobus/sim/yzaim/motor.py). A
remote (RTR) frame - python-can sends ``< send ID DLC >`` with DLC > 0 and no data bytes -
is dropped with one log line and no reply, as socketcand does (its rawmode has no remote
frames; it logs "Syntax error in send command" and answers nothing):
an ``< error ... >`` line would break python-can's session, which parses it as a frame. A
client starts receiving 20 ms after its rawmode ``< ok >``: python-can's handshake reads
with a single recv() and would fail if a frame were glued to that ``< ok >``. ``< echo >``
is answered; other commands get ``< error unsupported >``. Binds 127.0.0.1 by default.

Abuse (decisions; shared bounds in :mod:`servobus.sim.server_limits`):

* A malformed ``send`` (an identifier, length or data bytes that are not hex in range -
  ``-1`` included -, or bytes outside printable ASCII) is dropped without a reply, as
  socketcand does (its rawmode logs "Syntax error in send command" and answers nothing;
  python-can reads any ``< error ... >`` line as a frame and ends its session, issue 34).
  The first ``MAX_LOGGED_DROPS`` per session get one log line each, the rest are counted
  (``malformed_sends``). Any other message outside printable ASCII is answered ``< error
  command must be printable ASCII >``, an unknown command ``< error unsupported >``. Nothing
  malformed is relayed; the session stays open.
* The drives' port is a *gate*: it keeps a receive FIFO of ``RX_FIFO_FRAMES`` = 64 frames per
  sender and serves senders round robin, so one flooding client cannot starve another.
  A frame enters the bus (reaches any endpoint) only if every gate has room for it. Paced
  (bit-timing model on): a frame that does not fit is lost, as when a drive's CAN receive
  FIFO overflows (the specification gives no size: a servobus decision, docs/dyncan.md).
  ``--fast``: the sender waits for room instead (its TCP data is not read meanwhile), so
  nothing is lost and memory stays bounded.
* Every client's unread output is bounded (``MAX_OUTPUT_BYTES``); past it the client is
  dropped with one log line (it receives all bus traffic, so it cannot be paused).
* A client that half-closes after its requests gets the replies: its session lingers until
  the gates have taken its frames and ``REPLY_SETTLE_S`` more has passed.
* Connections beyond the cap get ``< error too many clients >`` and are closed.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import socket
import time
from collections import deque

from servobus.errors import ArgumentRangeError
from servobus.sim import server_limits as lim
from servobus.transport.base import Direction
from servobus.transport.can_bus import BitTiming, BusPacer, CanFrame, FrameTraceHook

RAWMODE_SETTLE_S = 0.020
MAX_MESSAGE = 256  # a socketcand message is far shorter; longer input is garbage
RX_FIFO_FRAMES = 64  # per sender at a gate (the drives' receive FIFO, see module doc)
LISTENER_FRAMES = 4096  # per sender at a plain in-process port (drops beyond)
MAX_LOGGED_DROPS = 10  # per session: malformed sends logged one line each, then counted
REPLY_SETTLE_S = 0.1  # half-closed session: time for replies after the gates took its frames
HALF_CLOSE_LINGER_S = 2.0  # ... at most this long in all
WHAT = "sim dyncan socketcand"
_HEX = re.compile(r"[0-9A-Fa-f]+")
_PRINTABLE = re.compile(rb"[\x20-\x7e]*")


def format_frame(frame: CanFrame) -> str:
    ident = (f"{frame.arbitration_id:08X}" if frame.is_extended_id
             else f"{frame.arbitration_id:03X}")
    sec = int(frame.timestamp)
    usec = round((frame.timestamp - sec) * 1e6) % 1_000_000
    return f"< frame {ident} {sec}.{usec:06d} {frame.data.hex().upper()} >"


def parse_send(tokens: list[str], timestamp: float | None = None,
               arrived: float | None = None) -> CanFrame:
    """``send ID DLC B0 B1 ...`` (tokens without the angle brackets), stamped ``timestamp``
    (wall clock, default now) and ``arrived`` (monotonic, when the hub knows it).

    Raises ValueError with a fixed ASCII reason: ID is 1-8 hex digits (more than 3 = 29-bit),
    DLC one hex digit 0..8, then exactly DLC data bytes of 1-2 hex digits each.
    """
    if len(tokens) < 3:
        raise ValueError("send needs an identifier and a length")
    ident_text, dlc_text, data_texts = tokens[1], tokens[2], tokens[3:]
    if not _HEX.fullmatch(ident_text) or len(ident_text) > 8:
        raise ValueError("identifier must be 1 to 8 hex digits")
    extended = len(ident_text) > 3
    ident = int(ident_text, 16)
    if ident > (0x1FFFFFFF if extended else 0x7FF):
        raise ValueError("identifier out of range")
    if not _HEX.fullmatch(dlc_text) or len(dlc_text) > 1 or int(dlc_text, 16) > 8:
        raise ValueError("length must be one hex digit 0 to 8")
    dlc = int(dlc_text, 16)
    if len(data_texts) != dlc:
        raise ValueError("number of data bytes does not match the length")
    if not all(_HEX.fullmatch(b) and len(b) <= 2 for b in data_texts):
        raise ValueError("data bytes must be 1 or 2 hex digits")
    return CanFrame(ident, bytes(int(b, 16) for b in data_texts),
                    time.time() if timestamp is None else timestamp, extended, arrived)


def is_remote_request(tokens: list[str]) -> bool:
    """``send ID DLC`` with a valid identifier, DLC 1..8 and no data bytes: how python-can's
    socketcand client writes a remote (RTR) frame."""
    if len(tokens) != 3 or not _HEX.fullmatch(tokens[2]) or len(tokens[2]) > 1:
        return False
    if not 1 <= int(tokens[2], 16) <= 8:
        return False
    try:
        parse_send([tokens[0], tokens[1], "0"])
    except ValueError:
        return False
    return True


class HubPort:
    """An in-process endpoint on the hub (a :class:`FramePort`).

    Frames wait in one FIFO per sender, bounded (``fifo_frames``), and :meth:`recv` takes
    them round robin across senders. A *gate* port (the drives) also decides whether a TCP
    client's frame may enter the bus at all (see the module doc).
    """

    def __init__(self, hub: SocketcandHub, timing: BitTiming | None = None, *,
                 gate: bool = False, fifo_frames: int | None = None) -> None:
        self._hub = hub
        self.gate = gate
        self.fifo_frames = fifo_frames or (RX_FIFO_FRAMES if gate else LISTENER_FRAMES)
        self._fifos: dict[object, deque[CanFrame]] = {}
        self._turns: deque[object] = deque()  # senders with frames waiting, in service order
        self._waiter: asyncio.Future[None] | None = None
        self._traces: list[FrameTraceHook] = []
        self._closed = False
        self.overflows = 0  # frames lost to a full FIFO
        self.pacer = BusPacer(timing) if timing is not None else None

    def has_room(self, sender: object) -> bool:
        fifo = self._fifos.get(sender)
        return self._closed or fifo is None or len(fifo) < self.fifo_frames

    def queued_from(self, sender: object) -> int:
        fifo = self._fifos.get(sender)
        return 0 if fifo is None else len(fifo)

    def deliver(self, frame: CanFrame, sender: object = None) -> None:
        if self._closed:
            return
        fifo = self._fifos.get(sender)
        if fifo is None:
            fifo = self._fifos[sender] = deque()
        if len(fifo) >= self.fifo_frames:
            self.overflows += 1
            return
        if not fifo:
            self._turns.append(sender)
        fifo.append(frame)
        now = time.monotonic()
        if self.pacer is not None:
            self.pacer.occupy(len(frame.data), now)
        for hook in self._traces:
            hook(Direction.RX, frame, now)
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

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
        if not self._turns:
            if self._closed:
                raise ConnectionError("hub port is closed")
            loop = asyncio.get_running_loop()
            waiter = self._waiter = loop.create_future()
            timer = None if timeout is None else loop.call_later(timeout, _resolve, waiter)
            try:
                await waiter
            finally:
                self._waiter = None
                if timer is not None:
                    timer.cancel()
            if not self._turns:
                if self._closed:
                    raise ConnectionError("hub port is closed")
                return None
        return self._take()

    def _take(self) -> CanFrame:
        sender = self._turns.popleft()
        fifo = self._fifos[sender]
        frame = fifo.popleft()
        if fifo:
            self._turns.append(sender)  # back of the line: round robin
        else:
            del self._fifos[sender]
        if self.gate:
            self._hub.room_made()
        return frame

    def add_trace(self, hook: FrameTraceHook) -> None:
        self._traces.append(hook)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._waiter is not None and not self._waiter.done():
                self._waiter.set_result(None)
            self._hub.detach(self)
            self._hub.room_made()


def _resolve(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


class _Session:
    """One TCP client."""

    def __init__(self, hub: SocketcandHub, writer: asyncio.StreamWriter) -> None:
        self.hub = hub
        self.writer = writer
        self.transport = writer.transport
        self.receiving = False
        self.dropped = False
        self._out = bytearray()  # written once per event-loop turn (one send for many frames)
        self._flush_scheduled = False
        self._wall = self._mono = 0.0  # when the TCP data being parsed reached the hub
        self.remote_frames = 0  # RTR frames dropped (socketcand rawmode has none)
        self.malformed_sends = 0  # dropped without a reply, as socketcand does

    def deliver(self, frame: CanFrame, sender: object = None) -> None:
        if self.receiving:
            self._write(format_frame(frame).encode("ascii"))

    def reply(self, text: str) -> None:
        self._write(text.encode("ascii"))

    def _write(self, data: bytes) -> None:
        transport = self.transport
        if self.dropped or transport.is_closing():
            return
        if lim.output_over_bound(transport, len(self._out) + len(data)):
            self.dropped = True
            self._out.clear()
            self.hub.dropped_clients += 1
            self.hub.detach(self)
            lim.drop_slow_reader(transport, WHAT)
            return
        self._out += data
        if not self._flush_scheduled:
            self._flush_scheduled = True
            asyncio.get_running_loop().call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        if self._out and not self.dropped and not self.transport.is_closing():
            self.transport.write(bytes(self._out))
        self._out.clear()

    async def run(self, reader: asyncio.StreamReader) -> None:
        self.reply("< hi >")
        buf = b""
        while not self.dropped:
            await asyncio.sleep(0)  # one chunk per loop turn: buffered input must not starve
            chunk = await reader.read(4096)  # the other sessions
            self._wall, self._mono = time.time(), time.monotonic()  # its frames' arrival
            if not chunk:
                if not self.dropped:
                    await self.hub.linger(self)  # half-closed: its replies are still owed
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
                if not _PRINTABLE.fullmatch(message):
                    if message.split(maxsplit=1)[:1] == [b"send"]:
                        self._drop_send("bytes outside printable ASCII")
                    else:
                        self.reply("< error command must be printable ASCII >")
                    continue
                await self._command(message.decode("ascii").split())

    async def _command(self, tokens: list[str]) -> None:
        if not tokens:
            return
        word = tokens[0]
        if word == "open":
            self.reply("< ok >")
        elif word == "rawmode":
            self.reply("< ok >")
            with contextlib.suppress(ConnectionError):
                await self.writer.drain()
            await asyncio.sleep(RAWMODE_SETTLE_S)
            self.receiving = True
        elif word == "send":
            try:
                frame = parse_send(tokens, self._wall, self._mono)
            except ValueError as exc:
                if is_remote_request(tokens):
                    self.remote_frames += 1
                    lim.logger.info("socketcand client sent a remote (RTR) frame %s: dropped, "
                             "socketcand rawmode has no remote frames", tokens[1])
                    return
                self._drop_send(str(exc))
                return
            await self.hub.publish_from_client(frame, self)
        elif word == "echo":
            self.reply("< echo >")
        else:
            self.reply("< error unsupported >")


    def _drop_send(self, reason: str) -> None:
        """A malformed ``send``: no reply (socketcand answers nothing; python-can would read
        an ``< error >`` line as a frame and end its session), one log line while few."""
        self.malformed_sends += 1
        if self.malformed_sends <= MAX_LOGGED_DROPS:
            lim.logger.info("socketcand client sent a malformed send (%s): dropped without a "
                            "reply, as socketcand does", reason)
            if self.malformed_sends == MAX_LOGGED_DROPS:
                lim.logger.info("socketcand client: further malformed sends on this session "
                                "are dropped without a log line")


Endpoint = HubPort | _Session


class SocketcandHub:
    """The virtual bus: TCP sessions and in-process ports; every frame reaches all others."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, *, lossless: bool = False,
                 max_clients: int = lim.DEFAULT_MAX_CLIENTS) -> None:
        self.host = host
        self.port = port
        self.lossless = lossless  # clients wait for room at the gates instead of losing frames
        self.cap = lim.ClientCap(max_clients, WHAT)
        self._endpoints: list[Endpoint] = []
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._room_waiters: list[asyncio.Future[None]] = []
        self.frames_from_tcp = 0
        self.frames_lost = 0  # client frames that found a gate's FIFO full (paced)
        self.dropped_clients = 0

    async def start(self) -> tuple[str, int]:
        url = f"{self.host}:{self.port}"
        try:
            self._server = await asyncio.start_server(self._on_client, self.host, self.port,
                                                      backlog=lim.LISTEN_BACKLOG)
        except OSError as exc:
            raise lim.listen_error("socketcand", url, exc) from None
        sock = self._server.sockets[0]
        requested = self.host
        self.host, self.port = sock.getsockname()[:2]
        lim.warn_if_exposed("the socketcand bus", requested, f"{self.host}:{self.port}")
        return self.host, self.port

    def open_port(self, timing: BitTiming | None = None, *, gate: bool = False) -> HubPort:
        """An in-process endpoint; ``gate=True`` for the drives' port (see the module doc)."""
        port = HubPort(self, timing, gate=gate)
        self._endpoints.append(port)
        return port

    def detach(self, endpoint: Endpoint) -> None:
        with contextlib.suppress(ValueError):
            self._endpoints.remove(endpoint)

    def publish(self, frame: CanFrame, sender: Endpoint) -> None:
        for endpoint in list(self._endpoints):
            if endpoint is not sender:
                endpoint.deliver(frame, sender)

    # ------------------------------------------------------------------ gates
    def _gates(self) -> list[HubPort]:
        return [e for e in self._endpoints if isinstance(e, HubPort) and e.gate]

    def has_room(self, sender: object) -> bool:
        return all(g.has_room(sender) for g in self._gates())

    def queued_from(self, sender: object) -> int:
        return sum(g.queued_from(sender) for g in self._gates())

    def room_made(self) -> None:
        waiters, self._room_waiters = self._room_waiters, []
        for fut in waiters:
            if not fut.done():
                fut.set_result(None)

    async def _room_changed(self) -> None:
        fut = asyncio.get_running_loop().create_future()
        self._room_waiters.append(fut)
        await fut

    async def publish_from_client(self, frame: CanFrame, session: _Session) -> None:
        """A TCP client's frame: onto the bus if the gates have room (see the module doc)."""
        while not self.has_room(session):
            if not self.lossless:
                self.frames_lost += 1
                return
            await self._room_changed()
        if session.dropped:
            return
        self.frames_from_tcp += 1
        self.publish(frame, session)

    async def linger(self, session: _Session) -> None:
        """Keep a half-closed session until its frames are taken and answered (bounded)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(HALF_CLOSE_LINGER_S):
                while self.queued_from(session):
                    await self._room_changed()
                await asyncio.sleep(REPLY_SETTLE_S)

    # ------------------------------------------------------------------ TCP clients
    async def _on_client(self, reader: asyncio.StreamReader,
                         writer: asyncio.StreamWriter) -> None:
        if not self.cap.admit():
            writer.write(b"< error too many clients >")
            writer.close()
            return
        task = asyncio.current_task()
        if task is not None:
            self._tasks.add(task)
        sock = writer.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        session = _Session(self, writer)
        self._endpoints.append(session)
        try:
            await session.run(reader)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self.cap.release()
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
        self.room_made()


def parse_socketcand_address(text: str) -> tuple[str, int]:
    """"HOST:PORT" -> (host, port); PORT 0 picks a free port."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ArgumentRangeError(f"socketcand address {text!r} must be HOST:PORT")
    if host.startswith("[") and host.endswith("]"):  # [::1]:PORT
        host = host[1:-1]
    return host or "127.0.0.1", int(port)
