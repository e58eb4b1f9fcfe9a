"""The fault run's TCP proxy between a machine and a drive, and its motion tap.

:class:`Proxy` forwards one listening port to a drive's port, a connection upstream per
connection accepted, like a serial-to-Ethernet bridge, a CAN gateway or a switch would; the
fault run (benchmarks/bench_faults.py) stops and restarts it (a bridge reboot: nothing
listens meanwhile) and cuts its connections (dropped connections). It is transparent: when
the drive's side closes, the machine's side is closed too, and a connection accepted while
nothing listens upstream is closed at once.

:class:`MotionTap` reads what the machine sends through every connection of one proxy with
the protocol's sniff decoder (servobus.sniff; on socketcand, the ``< send ... >`` frames)
and counts the *motion frames*: the frames that start a move (:data:`MOTION`). The run
moves each axis to a new absolute target each time, so a frame seen twice (the session
number of EtherNet/IP left out) is a motion command sent again: ``resent``.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections import Counter
from collections.abc import Callable

from servobus.sniff import BYTES, Decoder, decoders

#: protocol -> what a decoded host frame that starts a move looks like (servobus.sniff
#: texts). Stops (a speed of 0) are not motion. The run only commands absolute moves;
#: every other way to start motion is listed too, so an unasked one would be counted.
MOTION: dict[str, re.Pattern[str]] = {
    "dyn232": re.compile(r": (GO_ABSOLUTE_POS|GO_RELATIVE_POS|MAKE_LINEAR_LINE|"
                         r"MAKE_CIRCULAR_ARC|TURN_CONST_SPEED -?[1-9]|SQUARE_WAVE [1-9]|"
                         r"SIN_WAVE [1-9])"),
    "enip": re.compile(r"SET_ATTRIBUTE_SINGLE class 0x0F instance 0x[0-9A-F]+ "
                       r"(go_absolute_pos|go_relative_pos|turn_const_speed attribute 1 = "
                       r"-?[1-9]|square_wave|sine_wave)"),
    "easycan": re.compile(r"WRITE (absolute_position|incremental_position) "),
    "modbus": re.compile(r"write 0x[0-9A-F]+ (absolute_position|incremental_position)_low="),
}
MOTION["dyncan"] = MOTION["dyn232"]  # the same DMM functions and names

#: A socketcand frame the client sends (rawmode): ``< send 001 5 ff 12 1 e 10 >``.
SOCKETCAND_SEND = re.compile(rb"< send ([0-9A-Fa-f]+) ([0-9A-Fa-f]+)((?: [0-9A-Fa-f]{1,2})*) >")
_SESSION = re.compile(r"session 0x[0-9A-F]+")


class MotionTap:
    """The motion frames the machine sent through one proxy, across its restarts."""

    def __init__(self, protocol: str, decoder: Decoder | None = None) -> None:
        self.protocol = protocol
        self.decoder = decoder if decoder is not None else decoders()[protocol]
        self.pattern = MOTION[protocol]
        self.seen: Counter[str] = Counter()  # motion frame text -> times seen

    @property
    def frames(self) -> int:
        return sum(self.seen.values())

    @property
    def resent(self) -> int:
        """Motion frames seen more than once (each target is commanded once)."""
        return sum(n - 1 for n in self.seen.values())

    def _event(self, event: object) -> None:
        text = getattr(event, "text", "")
        if not getattr(event, "is_error", True) and self.pattern.search(text):
            self.seen[_SESSION.sub("session", text)] += 1

    def connection(self) -> Callable[[bytes], None]:
        """A feed for one connection's bytes towards the drive (a decoder of its own)."""
        if self.decoder.medium == BYTES:
            stream = self.decoder.stream()

            def feed_bytes(data: bytes) -> None:
                for event in stream.iter_feed(data):
                    self._event(event)

            return feed_bytes
        pending = bytearray()

        def feed_socketcand(data: bytes) -> None:
            pending.extend(data)
            end = pending.rfind(b">")
            if end < 0:
                return
            for m in SOCKETCAND_SEND.finditer(bytes(pending[:end + 1])):
                payload = bytes(int(b, 16) for b in m.group(3).split())
                self._event(self.decoder.frame(int(m.group(1), 16), payload))
            del pending[:end + 1]

        return feed_socketcand


class Proxy:
    """127.0.0.1:``port`` forwarded to 127.0.0.1:``upstream``; see the module docstring."""

    def __init__(self, port: int, upstream: int, tap: MotionTap) -> None:
        self.port = port
        self.upstream = upstream
        self.tap = tap
        self._server: asyncio.Server | None = None
        self._open: set[asyncio.Transport] = set()  # both sides of every connection
        self._tasks: set[asyncio.Task[None]] = set()

    @property
    def listening(self) -> bool:
        return self._server is not None

    @property
    def connections(self) -> int:
        return len(self._open) // 2

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._accepted, "127.0.0.1", self.port,
                                                  reuse_address=True)

    async def stop(self) -> None:
        """Nothing listens any more and every connection is gone (a bridge that reboots)."""
        server, self._server = self._server, None
        if server is not None:
            server.close()
        self.cut()
        if server is not None:
            await server.wait_closed()

    def cut(self) -> int:
        """Abort every connection (RST to both sides); the port still listens. How many."""
        cut = self.connections
        for transport in list(self._open):
            transport.abort()
        self._open.clear()
        return cut

    async def close(self) -> None:
        await self.stop()
        for task in list(self._tasks):
            task.cancel()
        for task in list(self._tasks):
            with contextlib.suppress(BaseException):
                await task

    def _accepted(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.ensure_future(self._forward(reader, writer))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _forward(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        down = writer.transport
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream)
        except OSError:
            down.abort()  # nothing upstream: the machine's connection ends at once
            return
        up = up_writer.transport
        if not self.listening or down.is_closing():  # stopped or cut meanwhile
            up.abort()
            down.abort()
            return
        self._open.update((down, up))
        pumps = [asyncio.ensure_future(self._pump(reader, up_writer, self.tap.connection())),
                 asyncio.ensure_future(self._pump(up_reader, writer, None))]
        try:
            await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in pumps:
                task.cancel()
            for transport in (down, up):
                self._open.discard(transport)
                transport.abort()
            for task in pumps:
                with contextlib.suppress(BaseException):
                    await task

    @staticmethod
    async def _pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                    tap: Callable[[bytes], None] | None) -> None:
        with contextlib.suppress(OSError):
            while data := await reader.read(65536):
                if tap is not None:
                    tap(data)
                writer.write(data)
                await writer.drain()
