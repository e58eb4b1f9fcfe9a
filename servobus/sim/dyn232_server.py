"""Serve one virtual DYN232M RS485 line over TCP (serial-to-TCP bridge) and/or a PTY.

* TCP: the raw serial byte stream, as a serial-to-TCP bridge would carry it, so pyserial's
  ``socket://127.0.0.1:PORT`` connects. Several clients may connect; each is its own host
  port on the line (its bytes are framed separately, so two clients never corrupt each
  other's packets) and each receives only the replies to its own packets.
* PTY: ``os.openpty()``; the slave path (``/dev/pts/N``) is opened like a serial port.
* Tap (optional): every byte of the line in both directions, in wire order, as raw bytes
  (host packets when their last byte arrived, replies when their last byte left), for
  ``servobus sniff --tap tcp://...``. What a tap client sends is ignored.

The server binds 127.0.0.1 unless an address is given explicitly. The sim server's event
loop uses ``select()`` (microsecond timeouts) so replies are released on time without
blocking the loop; see :mod:`servobus.sim.pacing`.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import selectors
import signal
import sys
import tty
from collections.abc import Callable, Sequence
from typing import TextIO
from urllib.parse import urlsplit

from servobus.errors import ArgumentRangeError
from servobus.sim.drive import VirtualDrive
from servobus.sim.dyn232_line import Dyn232Line
from servobus.sim.pacing import COARSE_S, FINE_COARSE_S, HostPort, LineRunner
from servobus.transport.base import Direction

DEFAULT_HOST = "127.0.0.1"


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
        self._clients: set[asyncio.Task[None]] = set()
        self._taps: set[asyncio.StreamWriter] = set()
        self._pty: tuple[int, int] | None = None
        self.runner.add_tap(self._to_taps)

    @property
    def drives(self) -> list[VirtualDrive]:
        return self.line.drives

    # ------------------------------------------------------------------ TCP line
    async def listen_tcp(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        """Serve the line on TCP; return the bound (host, port)."""
        self.runner.start()
        server = await asyncio.start_server(self._client, host, port)
        self._servers.append(server)
        sockname = server.sockets[0].getsockname()
        return str(sockname[0]), int(sockname[1])

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._clients.add(task)
        port = self.runner.open_port(_writer_sink(writer))
        try:
            while data := await reader.read(4096):
                self.runner.submit(port, data)
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            port.closed = True
            writer.close()
            if task is not None:
                self._clients.discard(task)

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
        server = await asyncio.start_server(self._tap_client, host, port)
        self._servers.append(server)
        sockname = server.sockets[0].getsockname()
        return str(sockname[0]), int(sockname[1])

    async def _tap_client(self, reader: asyncio.StreamReader,
                          writer: asyncio.StreamWriter) -> None:
        self._taps.add(writer)
        try:
            while await reader.read(4096):
                pass  # a tap is read-only
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            self._taps.discard(writer)
            writer.close()

    def _to_taps(self, direction: Direction, data: bytes, when: float) -> None:
        for writer in list(self._taps):
            if writer.is_closing():
                self._taps.discard(writer)
            else:
                writer.write(data)

    # ------------------------------------------------------------------ shutdown
    async def close(self) -> None:
        for server in self._servers:
            server.close()
        for task in list(self._clients):
            task.cancel()
        for writer in list(self._taps):
            writer.close()
        if self._clients:
            await asyncio.gather(*self._clients, return_exceptions=True)
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


def _writer_sink(writer: asyncio.StreamWriter) -> Callable[[bytes], None]:
    def sink(data: bytes) -> None:
        if not writer.is_closing():
            writer.write(data)

    return sink


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
