"""Serve one virtual serial line over TCP (a serial-to-TCP bridge), a PTY and a tap (any
protocol): the mechanics every ``servobus sim <serial protocol>`` server shares.

A protocol supplies a *runner* (:class:`LineRunnerLike`: its line, framing and pacing) whose
host ports (:class:`HostPortLike`) receive that host's replies; this module moves bytes:

* TCP: the raw serial byte stream, as a serial-to-TCP bridge would carry it, so pyserial's
  ``socket://127.0.0.1:PORT`` connects. Several clients may connect; each is its own host
  port on the line (its bytes are framed separately, so two clients never corrupt each
  other's frames) and each receives only the replies to its own frames.
* PTY: ``os.openpty()``; the slave path (``/dev/pts/N``) is opened like a serial port.
* Tap (optional): every byte of the line in both directions, in wire order, as the runner
  reports it, for ``servobus sniff --tap tcp://...``. What a tap client sends is ignored.

TCP connections and taps are :class:`asyncio.Protocol` objects, not StreamReader tasks: a
host's bytes go from ``data_received`` straight into the runner's ``submit`` and replies
straight to ``transport.write`` (one event-loop wake-up per frame, no task switch). The
runner's tap hook is only installed once a tap listener exists.

Abuse (decisions; bounds in :mod:`servobus.sim.server_limits`):

* Fair service: a chunk longer than ``QUANTUM`` bytes is queued and handed to the line
  ``QUANTUM`` bytes per event-loop turn, reading from that client paused meanwhile, so one
  client's flood costs every other client at most one quantum (~1 ms) per turn.
* Backpressure: a client that does not read its replies is no longer read from once
  ``WRITE_HIGH_WATER`` bytes wait for it; a tap (it cannot be paused) past
  ``MAX_OUTPUT_BYTES`` is dropped with one log line.
* Replies pending for a client that has gone are dropped, never written (the runner's
  ``close_port``).
* A client that half-closes (shuts down its sending side) still gets the replies to what
  it sent; the connection closes once they are out (the port's ``pending`` count and
  ``on_idle`` callback).
* Connections beyond the cap are accepted and closed at once (one log line per episode).

The server binds 127.0.0.1 unless an address is given explicitly, and warns (one log line)
when told to bind beyond loopback. :func:`run_in_fine_loop` runs a server on
:class:`servobus.sim.fine_selector.FineEpollSelector`: epoll for any number of connections,
with microsecond timeouts so paced replies are released on time.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
import tty
from collections.abc import Callable, Coroutine
from typing import Any, Generic, Protocol, TextIO, TypeVar
from urllib.parse import urlsplit

from servobus.errors import ArgumentRangeError
from servobus.sim import server_limits as lim
from servobus.sim.fine_selector import fine_event_loop
from servobus.transport.base import Direction, TraceHook

DEFAULT_HOST = "127.0.0.1"
CLOSE_TIMEOUT_S = 2.0  # close(): how long to wait for client connections to go
QUANTUM = 1024  # bytes of one client handed to the line per event-loop turn (fairness)


class HostPortLike(Protocol):
    """One host on the line, as the runner keeps it."""

    closed: bool
    pending: int  # replies scheduled for this host, not yet delivered
    on_idle: Callable[[], None] | None  # called when ``pending`` drops to 0


P = TypeVar("P", bound=HostPortLike)


class LineRunnerLike(Protocol[P]):
    """A protocol's line in time: host bytes in, replies out through each port."""

    def start(self) -> None: ...
    def open_port(self, deliver: Callable[[bytes], None]) -> P: ...
    def close_port(self, port: P) -> None: ...
    def submit(self, port: P, data: bytes) -> None: ...
    def add_tap(self, hook: TraceHook) -> None: ...
    async def close(self) -> None: ...


def parse_listen_url(url: str) -> tuple[str, int]:
    """``tcp://HOST:PORT`` (also ``HOST:PORT``, ``:PORT``, ``PORT``) -> (host, port).

    A missing host means 127.0.0.1, never all interfaces: exposing a drive line to the
    network has to be asked for explicitly (``tcp://0.0.0.0:PORT``).
    """
    text = url.strip()
    if text.isdigit():
        text = f"tcp://:{text}"
    elif "://" not in text:
        text = f"tcp://{text}"
    parts = urlsplit(text)
    if parts.scheme != "tcp":
        raise ArgumentRangeError(f"listen URL must be tcp://HOST:PORT, got {url!r}")
    try:
        port = parts.port
    except ValueError:
        raise ArgumentRangeError(f"bad port in {url!r} (0..65535)") from None
    if port is None:
        raise ArgumentRangeError(f"listen URL needs a port (0 = any free port): {url!r}")
    return parts.hostname or DEFAULT_HOST, port


def format_tcp_url(host: str, port: int) -> str:
    return f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}"


class LineServer(Generic[P]):
    """One virtual line (its runner) with TCP, PTY and tap endpoints."""

    def __init__(self, runner: LineRunnerLike[P], *, what: str,
                 max_clients: int = lim.DEFAULT_MAX_CLIENTS) -> None:
        self.runner = runner
        self.what = what  # how log lines name this server, e.g. "sim dyn232"
        self.cap = lim.ClientCap(max_clients, what)  # TCP clients and taps together
        self.dropped_clients = 0  # dropped for leaving too much output unread
        self._servers: list[asyncio.Server] = []
        self._clients: set[_LineConnection[P]] = set()
        self._taps: set[asyncio.Transport] = set()
        self._tapped = False  # the runner's tap hook is added with the first tap listener
        self._pty: tuple[int, int] | None = None

    @property
    def client_count(self) -> int:
        """TCP line clients connected now."""
        return len(self._clients)

    # ------------------------------------------------------------------ TCP line
    async def listen_tcp(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        """Serve the line on TCP; return the bound (host, port)."""
        self.runner.start()
        return await self._listen("line", host, port, lambda: _LineConnection(self),
                                  lim.MOVES_MOTORS)

    async def _listen(self, what: str, host: str, port: int,
                      factory: Callable[[], asyncio.Protocol],
                      consequence: str) -> tuple[str, int]:
        loop = asyncio.get_running_loop()
        url = format_tcp_url(host, port)
        try:
            server = await loop.create_server(factory, host, port,
                                              backlog=lim.LISTEN_BACKLOG)
        except OSError as exc:
            raise lim.listen_error(f"the {self.what} {what}", url, exc) from None
        self._servers.append(server)
        sockname = server.sockets[0].getsockname()
        bound = str(sockname[0]), int(sockname[1])
        lim.warn_if_exposed(f"the {self.what} {what}", host, format_tcp_url(*bound), consequence)
        return bound

    # ------------------------------------------------------------------ PTY line
    def open_pty(self) -> str:
        """Create a pseudo-terminal wired to the line; return the slave path."""
        if self._pty is not None:
            raise RuntimeError("the PTY is already open")
        self.runner.start()
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline: a clean 8-bit serial line
        os.set_blocking(master, False)
        self._pty = (master, slave)  # keep the slave open: no EIO when a client closes
        port = self.runner.open_port(lambda data: _pty_write(master, data))
        asyncio.get_running_loop().add_reader(master, self._pty_readable, master, port)
        return os.ttyname(slave)

    def _pty_readable(self, master: int, port: P) -> None:
        try:
            data = os.read(master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # EIO: no slave left; keep serving for the next opener
            return
        self.runner.submit(port, data)

    # ------------------------------------------------------------------ tap
    async def listen_tap(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        if not self._tapped:  # no tap hook before: the untapped line skips the tap work
            self._tapped = True
            self.runner.add_tap(self._to_taps)
        return await self._listen("tap", host, port, lambda: _TapConnection(self),
                                  lim.SEES_TRAFFIC)

    @property
    def tap_count(self) -> int:
        """Tap clients connected now (tests wait for it rather than guess an accept delay)."""
        return len(self._taps)

    def _to_taps(self, direction: Direction, data: bytes, when: float) -> None:
        for transport in list(self._taps):
            if transport.is_closing():
                self._taps.discard(transport)
            elif lim.output_over_bound(transport, len(data)):
                self._taps.discard(transport)
                self.dropped_clients += 1
                lim.drop_slow_reader(transport, f"{self.what} tap")
            else:
                transport.write(data)

    # ------------------------------------------------------------------ shutdown
    async def close(self) -> None:
        for server in self._servers:
            server.close()
        closing = [conn.close() for conn in list(self._clients)]
        for transport in list(self._taps):
            transport.close()
        self._taps.clear()
        if closing:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.gather(*closing), CLOSE_TIMEOUT_S)
        for server in self._servers:
            with contextlib.suppress(Exception):
                await server.wait_closed()
        self._servers.clear()
        if self._pty is not None:
            master, slave = self._pty
            self._pty = None
            asyncio.get_running_loop().remove_reader(master)
            os.close(master)
            os.close(slave)
        await self.runner.close()


class _LineConnection(asyncio.Protocol, Generic[P]):
    """One TCP host on the line: its own host port, bytes straight from ``data_received``.

    No StreamReader and no task per client: each chunk goes to the runner's ``submit`` from
    the transport's callback (a long chunk one ``QUANTUM`` per loop turn), and replies (the
    port's ``deliver``) go to ``transport.write``, those of one chunk in one write.
    """

    def __init__(self, server: LineServer[P]) -> None:
        self._server = server
        self._loop = asyncio.get_running_loop()
        self._transport: asyncio.Transport | None = None
        self._port: P | None = None
        self._admitted = False
        self._backlog = bytearray()  # received, not yet handed to the line
        self._scheduled = False  # a _serve_backlog call is queued
        self._reading_paused = False
        self._writing_paused = False
        self._batch: bytearray | None = None  # replies collected while a chunk is submitted
        self._eof = False
        self._lost: asyncio.Future[None] = self._loop.create_future()

    # ---------------------------------------------------------------- asyncio callbacks
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        if not self._server.cap.admit():
            transport.close()  # the refusal: accepted and closed at once
            return
        self._admitted = True
        transport.set_write_buffer_limits(high=lim.WRITE_HIGH_WATER)
        self._port = self._server.runner.open_port(self._deliver)
        self._port.on_idle = self._maybe_finish
        self._server._clients.add(self)

    def data_received(self, data: bytes) -> None:
        if self._port is None or self._port.closed:
            return
        if self._backlog or len(data) > QUANTUM:
            self._backlog += data
            self._pause_reading()
            self._schedule()
        else:
            self._submit(data)

    def eof_received(self) -> bool | None:
        """Half-close: answer what was sent, then close (keep the transport open till then)."""
        self._eof = True
        if self._port is None or self._port.closed:
            return None
        return not self._finished()

    def pause_writing(self) -> None:
        self._writing_paused = True
        self._pause_reading()  # stop taking requests until the client reads its replies

    def resume_writing(self) -> None:
        self._writing_paused = False
        if self._backlog:
            self._schedule()
        else:
            self._resume_reading()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._admitted:
            self._admitted = False
            self._server.cap.release()
        self._stop_replies()
        self._backlog.clear()
        self._server._clients.discard(self)
        if not self._lost.done():
            self._lost.set_result(None)

    # ---------------------------------------------------------------- line side
    def _submit(self, data: bytes) -> None:
        assert self._port is not None
        self._batch = bytearray()
        try:
            self._server.runner.submit(self._port, data)
        finally:
            out, self._batch = self._batch, None
        if out:
            self._write(bytes(out))

    def _schedule(self) -> None:
        if not self._scheduled:
            self._scheduled = True
            self._loop.call_soon(self._serve_backlog)  # behind every other ready callback

    def _serve_backlog(self) -> None:
        self._scheduled = False
        if self._port is None or self._port.closed:
            self._backlog.clear()
            return
        if self._writing_paused:
            return  # resume_writing() continues
        chunk = bytes(self._backlog[:QUANTUM])
        del self._backlog[:QUANTUM]
        self._submit(chunk)
        if self._backlog:
            self._schedule()
        else:
            self._resume_reading()
            self._maybe_finish()

    def _deliver(self, data: bytes) -> None:
        if self._batch is not None:
            self._batch += data
        else:
            self._write(data)

    def _write(self, data: bytes) -> None:
        transport = self._transport
        if transport is None or transport.is_closing():
            return
        if lim.output_over_bound(transport, len(data)):
            self._server.dropped_clients += 1
            self._stop_replies()
            lim.drop_slow_reader(transport, self._server.what)
            return
        transport.write(data)

    # ---------------------------------------------------------------- flow and shutdown
    def _pause_reading(self) -> None:
        if not self._reading_paused and self._transport is not None \
                and not self._transport.is_closing():
            self._reading_paused = True
            self._transport.pause_reading()

    def _resume_reading(self) -> None:
        if self._reading_paused and not self._writing_paused and not self._backlog:
            self._reading_paused = False
            if self._transport is not None and not self._transport.is_closing():
                self._transport.resume_reading()

    def _finished(self) -> bool:
        return not self._backlog and (self._port is None or not self._port.pending)

    def _maybe_finish(self) -> None:
        """After a half-close: close once every reply owed has been written."""
        if self._eof and self._finished() and self._transport is not None:
            self._transport.close()  # flushes what is buffered first

    def _stop_replies(self) -> None:
        if self._port is not None and not self._port.closed:
            self._server.runner.close_port(self._port)  # queued paced replies: dropped

    async def close(self) -> None:
        self._stop_replies()
        if self._transport is not None:
            self._transport.close()
        await self._lost


class _TapConnection(asyncio.Protocol, Generic[P]):
    """A read-only tap client: receives every byte of the line; what it sends is ignored."""

    def __init__(self, server: LineServer[P]) -> None:
        self._server = server
        self._transport: asyncio.Transport | None = None
        self._admitted = False

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        if not self._server.cap.admit():
            transport.close()
            return
        self._admitted = True
        self._server._taps.add(transport)

    def data_received(self, data: bytes) -> None:
        pass  # a tap is read-only

    def connection_lost(self, exc: Exception | None) -> None:
        if self._admitted:
            self._admitted = False
            self._server.cap.release()
        if self._transport is not None:
            self._server._taps.discard(self._transport)


def _pty_write(master: int, data: bytes) -> None:
    """Like a UART: bytes nobody reads are lost once the PTY buffer is full."""
    with contextlib.suppress(BlockingIOError, InterruptedError, OSError):
        os.write(master, data)


S = TypeVar("S", bound=LineServer[Any])


async def serve_line(
    server: S,
    *,
    listen: tuple[str, int] | None = (DEFAULT_HOST, 0),
    pty: bool = False,
    tap: tuple[str, int] | None = None,
    duration: float | None = None,
    out: TextIO | None = None,
    ready: Callable[[], None] | None = None,
) -> S:
    """Run ``server`` until SIGINT/SIGTERM or ``duration`` seconds; print where it listens
    (one line per endpoint on ``out``, flushed at once, so scripts and tests can read it).

    ``ready`` is called once every endpoint is up. Raises
    :class:`servobus.sim.server_limits.ListenError` when an address cannot be bound.
    """
    stream = out if out is not None else sys.stdout
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    installed: list[signal.Signals] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(sig, stop.set)
            installed.append(sig)
    try:
        if listen is not None:
            host, port = await server.listen_tcp(*listen)
            print(f"listening on {format_tcp_url(host, port)}", file=stream, flush=True)
        if pty:
            print(f"pty {server.open_pty()}", file=stream, flush=True)
        if tap is not None:
            host, port = await server.listen_tap(*tap)
            print(f"tap on {format_tcp_url(host, port)}", file=stream, flush=True)
        if ready is not None:
            ready()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), duration)
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
        await server.close()
    return server


T = TypeVar("T")


def run_in_fine_loop(main: Coroutine[Any, Any, T]) -> T:
    """Blocking entry point for the CLI: ``main`` on an epoll loop with fine timeouts."""
    with asyncio.Runner(loop_factory=fine_event_loop) as runner:
        return runner.run(main)
