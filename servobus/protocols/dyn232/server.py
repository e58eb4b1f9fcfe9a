"""Serve one virtual DYN232M RS485 line over TCP (serial-to-TCP bridge) and/or a PTY.

* TCP: the raw serial byte stream, as a serial-to-TCP bridge would carry it, so pyserial's
  ``socket://127.0.0.1:PORT`` connects. Several clients may connect; each is its own host
  port on the line (its bytes are framed separately, so two clients never corrupt each
  other's packets) and each receives only the replies to its own packets.
* PTY: ``os.openpty()``; the slave path (``/dev/pts/N``) is opened like a serial port.
* Tap (optional): every byte of the line in both directions, in wire order, as raw bytes
  (host packets when their last byte arrived, replies when their last byte left), for
  ``servobus sniff --tap tcp://...``. What a tap client sends is ignored.

TCP connections and taps are :class:`asyncio.Protocol` objects, not StreamReader tasks: a
host's bytes go from ``data_received`` straight into :meth:`LineRunner.submit` and replies
straight to ``transport.write`` (one event-loop wake-up per packet, no task switch). The
runner's tap hook is only installed once a tap listener exists, so an untapped line skips
the tap bookkeeping.

The server binds 127.0.0.1 unless an address is given explicitly. The sim server's event
loop uses ``select()`` (microsecond timeouts) so replies are released on time without
blocking the loop; see :mod:`servobus.protocols.dyn232.pacing`.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import os
import selectors
import signal
import sys
import tty
from collections.abc import Sequence
from typing import TextIO
from urllib.parse import urlsplit

from servobus.errors import ArgumentRangeError
from servobus.protocols.dyn232.line import Dyn232Line
from servobus.protocols.dyn232.pacing import COARSE_S, FINE_COARSE_S, HostPort, LineRunner
from servobus.sim.drive import VirtualDrive
from servobus.transport.base import Direction

DEFAULT_HOST = "127.0.0.1"
CLOSE_TIMEOUT_S = 2.0  # close(): how long to wait for client connections to go


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


class Dyn232Server:
    """One virtual line (drives + pacing) with its TCP, PTY and tap endpoints."""

    def __init__(self, drives: Sequence[VirtualDrive], *, paced: bool = True,
                 coarse_s: float | None = None) -> None:
        self.line = Dyn232Line(drives)
        self.runner = LineRunner(self.line, paced=paced,
                                 coarse_s=COARSE_S if coarse_s is None else coarse_s)
        self._servers: list[asyncio.Server] = []
        self._clients: set[_LineConnection] = set()
        self._taps: set[asyncio.Transport] = set()
        self._tapped = False  # the runner's tap hook is added with the first tap listener
        self._pty: tuple[int, int] | None = None

    @property
    def drives(self) -> list[VirtualDrive]:
        return self.line.drives

    # ------------------------------------------------------------------ TCP line
    async def listen_tcp(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        """Serve the line on TCP; return the bound (host, port)."""
        self.runner.start()
        loop = asyncio.get_running_loop()
        server = await loop.create_server(lambda: _LineConnection(self), host, port)
        self._servers.append(server)
        sockname = server.sockets[0].getsockname()
        return str(sockname[0]), int(sockname[1])

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

    def _pty_readable(self, master: int, port: HostPort) -> None:
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
        loop = asyncio.get_running_loop()
        server = await loop.create_server(lambda: _TapConnection(self._taps), host, port)
        self._servers.append(server)
        sockname = server.sockets[0].getsockname()
        return str(sockname[0]), int(sockname[1])

    @property
    def tap_count(self) -> int:
        """Tap clients connected now (tests wait for it rather than guess an accept delay)."""
        return len(self._taps)

    def _to_taps(self, direction: Direction, data: bytes, when: float) -> None:
        for transport in list(self._taps):
            if transport.is_closing():
                self._taps.discard(transport)
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


class _LineConnection(asyncio.Protocol):
    """One TCP host on the line: its own HostPort, bytes straight from ``data_received``.

    No StreamReader and no task per client: each chunk goes to ``LineRunner.submit`` from the
    transport's callback, and replies (``HostPort.deliver``) go to ``transport.write``.
    """

    def __init__(self, server: Dyn232Server) -> None:
        self._server = server
        self._transport: asyncio.Transport | None = None
        self._port: HostPort | None = None
        self._lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self._port = self._server.runner.open_port(transport.write)
        self._submit = functools.partial(self._server.runner.submit, self._port)
        self._server._clients.add(self)

    def data_received(self, data: bytes) -> None:
        self._submit(data)

    def eof_received(self) -> bool | None:
        self._stop_replies()  # the transport closes itself (returning None)
        return None

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_replies()
        self._server._clients.discard(self)
        if not self._lost.done():
            self._lost.set_result(None)

    def _stop_replies(self) -> None:
        if self._port is not None:
            self._port.closed = True  # paced replies still queued are not written

    async def close(self) -> None:
        self._stop_replies()
        if self._transport is not None:
            self._transport.close()
        await self._lost


class _TapConnection(asyncio.Protocol):
    """A read-only tap client: receives every byte of the line; what it sends is ignored."""

    def __init__(self, taps: set[asyncio.Transport]) -> None:
        self._taps = taps
        self._transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self._taps.add(transport)

    def data_received(self, data: bytes) -> None:
        pass  # a tap is read-only

    def connection_lost(self, exc: Exception | None) -> None:
        if self._transport is not None:
            self._taps.discard(self._transport)


def _pty_write(master: int, data: bytes) -> None:
    """Like a UART: bytes nobody reads are lost once the PTY buffer is full."""
    with contextlib.suppress(BlockingIOError, InterruptedError, OSError):
        os.write(master, data)


async def serve(
    drives: Sequence[VirtualDrive],
    *,
    listen: tuple[str, int] | None = (DEFAULT_HOST, 0),
    pty: bool = False,
    tap: tuple[str, int] | None = None,
    paced: bool = True,
    duration: float | None = None,
    out: TextIO | None = None,
    coarse_s: float | None = None,
) -> Dyn232Server:
    """Run a line until SIGINT/SIGTERM or ``duration`` seconds; print where it listens."""
    stream = out if out is not None else sys.stdout
    server = Dyn232Server(drives, paced=paced, coarse_s=coarse_s)
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
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), duration)
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
        await server.close()
    return server


def select_loop() -> asyncio.AbstractEventLoop:
    """An event loop on select(): microsecond timeouts, so paced replies leave on time."""
    return asyncio.SelectorEventLoop(selectors.SelectSelector())


def run_server(
    drives: Sequence[VirtualDrive],
    *,
    listen: tuple[str, int] | None = (DEFAULT_HOST, 0),
    pty: bool = False,
    tap: tuple[str, int] | None = None,
    paced: bool = True,
    duration: float | None = None,
    out: TextIO | None = None,
) -> Dyn232Server:
    """Blocking entry point for the CLI: ``serve`` on a select()-based loop."""
    with asyncio.Runner(loop_factory=select_loop) as runner:
        return runner.run(serve(drives, listen=listen, pty=pty, tap=tap, paced=paced,
                                duration=duration, out=out, coarse_s=FINE_COARSE_S))
