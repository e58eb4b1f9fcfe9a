"""The control channel over TCP: JSON lines on loopback (protocol: docs/sim-control.md).

One request per line, one reply per line, in order, on any number of connections (up to
``max_clients``). Bounded: a line longer than ``MAX_LINE`` bytes is answered with a
``too_long`` error and skipped up to its newline; a line that is not a JSON object gets a
``malformed`` error; the session goes on after either. A client that does not read its
replies is no longer read from (asyncio flow control). Binds 127.0.0.1 unless told
otherwise, and warns once when told to bind beyond loopback: whoever connects can move the
motors and inject faults.

One log line per event on the ``servobus.sim`` logger: a connection opens or closes, a
command that changes something (info), a refused request (warning, the first
``MAX_LOGGED_ERRORS`` per connection). Reads (``state``, ``outputs``, ``ping``) log at debug
level only, so a host polling the state does not flood the log.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import sys
from collections.abc import Sequence
from typing import Any, TextIO

from servobus.sim import server_limits as lim
from servobus.sim.core.control import ChannelControl, Reply
from servobus.sim.dmm.control import DriveControl
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.line_server import DEFAULT_HOST, format_tcp_url
from servobus.sim.wall_clock import RealtimeClock, cancel_and_wait

MAX_LINE = 4096  # bytes of one request line
DEFAULT_MAX_CLIENTS = 16
MAX_LOGGED_ERRORS = 10  # per connection; further refusals are counted, not logged
READ_CHUNK = 65_536
WHAT = "sim control"

log = lim.logger


def _dumps(reply: Reply) -> bytes:
    return (json.dumps(reply, separators=(", ", ": ")) + "\n").encode()


class ControlServer:
    """Serves a family's :class:`ChannelControl` (DMM: :class:`DriveControl`; YZ-AIM:
    ``servobus.sim.yzaim.control.MotorControl``) on one TCP port."""

    def __init__(self, control: ChannelControl[Any], *, max_clients: int = DEFAULT_MAX_CLIENTS,
                 max_line: int = MAX_LINE) -> None:
        self.control = control
        self.max_line = max_line
        self.cap = lim.ClientCap(max_clients, WHAT)
        self.requests = 0
        self.refused = 0  # requests answered with an error
        self._sock: socket.socket | None = None
        self._server: asyncio.Server | None = None
        self._task: asyncio.Task[None] | None = None
        self.address: tuple[str, int] | None = None

    @property
    def url(self) -> str:
        if self.address is None:
            raise RuntimeError("the control server is not bound")
        return format_tcp_url(*self.address)

    def bind(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        """Bind and listen now (synchronously, so the port is known at once); ListenError
        when the address cannot be bound."""
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        url = format_tcp_url(host, port)
        try:
            sock = socket.create_server((host, port), family=family,
                                        backlog=lim.LISTEN_BACKLOG)
        except OSError as exc:
            raise lim.listen_error(WHAT, url, exc) from None
        sock.setblocking(False)
        self._sock = sock
        bound = sock.getsockname()
        self.address = (host, int(bound[1]))
        lim.warn_if_exposed(WHAT, host, self.url, "can move the motors and inject faults")
        return self.address

    def start(self) -> asyncio.Task[None]:
        """Serve on the running loop until :meth:`close` (or the loop ends)."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self.serve(),
                                                                name="sim-control")
        return self._task

    async def serve(self) -> None:
        if self._sock is None:
            self.bind()
        self._server = await asyncio.start_server(self._client, sock=self._sock)
        async with self._server:
            await self._server.serve_forever()

    async def close(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            await cancel_and_wait(task)
        elif self._sock is not None:
            self._sock.close()

    # ------------------------------------------------------------------ one connection
    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        who = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) and len(peer) >= 2 else "?"
        if not self.cap.admit():
            writer.write(_dumps({"ok": False, "kind": "busy", "error":
                                 f"{self.cap.limit} connections already; try again later"}))
            writer.close()
            return
        log.info("%s: %s connected", WHAT, who)
        session = _Session(self, writer, who)
        try:
            await session.run(reader)
        except (ConnectionError, OSError):
            pass
        finally:
            self.cap.release()
            writer.close()
            with contextlib.suppress(ConnectionError, OSError, asyncio.CancelledError):
                await writer.wait_closed()
            log.info("%s: %s disconnected after %d request(s)", WHAT, who, session.requests)


class _Session:
    def __init__(self, server: ControlServer, writer: asyncio.StreamWriter, who: str) -> None:
        self.server = server
        self.writer = writer
        self.who = who
        self.requests = 0
        self.errors = 0

    async def run(self, reader: asyncio.StreamReader) -> None:
        limit = self.server.max_line
        buf = bytearray()
        skipping = False  # inside a line already refused as too long
        while True:
            chunk = await reader.read(READ_CHUNK)
            if not chunk:
                return
            buf += chunk
            while (end := buf.find(b"\n")) >= 0:
                line = bytes(buf[:end])
                del buf[:end + 1]
                if skipping:
                    skipping = False
                elif len(line) > limit:
                    await self._refuse("too_long", f"a line holds at most {limit} bytes")
                else:
                    await self._line(line)
            if len(buf) > limit:
                if not skipping:
                    await self._refuse("too_long", f"a line holds at most {limit} bytes")
                skipping = True
                buf.clear()

    async def _line(self, line: bytes) -> None:
        if not line.strip():
            return  # blank lines are ignored (interactive use)
        try:
            request: Any = json.loads(line)
        except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
            await self._refuse("malformed", f"not JSON: {str(exc)[:80]}")
            return
        self.requests += 1
        self.server.requests += 1
        reply = self.server.control.execute(request)
        if reply["ok"]:
            self._log_done(request, reply)
        else:
            self._log_refused(reply)
        await self._send(reply)

    async def _refuse(self, kind: str, message: str) -> None:
        reply = {"ok": False, "kind": kind, "error": message}
        self._log_refused(reply)
        await self._send(reply)

    def _log_done(self, request: dict[str, Any], reply: Reply) -> None:
        command = self.server.control.commands[request["cmd"]]
        args = " ".join(f"{k}={v}" for k, v in request.items() if k not in ("cmd", "id", "seq"))
        target = f"id {reply['id']} " if "id" in reply else ""
        level = logging.INFO if command.changes else logging.DEBUG
        log.log(level, "%s: %s: %s%s %s", WHAT, self.who, target, command.name, args)

    def _log_refused(self, reply: Reply) -> None:
        self.server.refused += 1
        self.errors += 1
        if self.errors <= MAX_LOGGED_ERRORS:
            log.warning("%s: %s: refused (%s): %s", WHAT, self.who, reply["kind"],
                        reply["error"])
            if self.errors == MAX_LOGGED_ERRORS:
                log.warning("%s: %s: further refusals on this connection are not logged",
                            WHAT, self.who)

    async def _send(self, reply: Reply) -> None:
        self.writer.write(_dumps(reply))
        await self.writer.drain()  # a client that does not read is no longer read from


def print_endpoint(server: ControlServer, out: TextIO | None = None) -> None:
    """``control on tcp://HOST:PORT`` on stdout, flushed (scripts and tests read it)."""
    print(f"control on {server.url}", file=out if out is not None else sys.stdout, flush=True)


def start_control(endpoint: tuple[str, int] | None, drives: Sequence[VirtualDrive], *,
                  clock: RealtimeClock | None = None) -> ControlServer | None:
    """Bind, print where, and serve DMM ``drives`` on the running loop (None: nothing to
    do) - what ``--control`` of a ``servobus sim <protocol>`` does once its server is up.

    ``clock`` is the server's wall-clock mapping when it has one at hand; otherwise one is
    made from the drives' own time. Raises ListenError when the address cannot be bound."""
    if endpoint is None:
        return None
    clock = clock if clock is not None else RealtimeClock(drives)
    return serve_control(endpoint, DriveControl(drives, sync=clock.sync))


def serve_control(endpoint: tuple[str, int], control: ChannelControl[Any]) -> ControlServer:
    """Bind, print where, and serve ``control`` (any family's) on the running loop."""
    server = ControlServer(control)
    server.bind(*endpoint)
    print_endpoint(server)
    server.start()
    return server
