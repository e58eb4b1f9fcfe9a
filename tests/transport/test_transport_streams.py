"""TcpStream and SerialStream (pyserial URLs) against local echo servers and loop://."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest

from servobus.errors import ServobusError
from servobus.transport.base import ByteStream, Direction
from servobus.transport.serial_stream import SerialStream
from servobus.transport.tcp_stream import TcpStream, parse_host_port
from servobus.transport.trace import TraceRecorder

pytestmark = pytest.mark.timeout(15)


async def read_exactly(stream: ByteStream, n: int, timeout: float = 2.0) -> bytes:
    out = b""
    async with asyncio.timeout(timeout):
        while len(out) < n:
            out += await stream.read(n - len(out))
    return out


@asynccontextmanager
async def echo_server() -> AsyncIterator[tuple[str, int]]:
    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while data := await reader.read(4096):
                writer.write(data)
        except ConnectionError:
            pass
        finally:
            writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    host, port = server.sockets[0].getsockname()[:2]
    try:
        yield str(host), int(port)
    finally:
        server.close()
        await server.wait_closed()


def test_parse_host_port() -> None:
    assert parse_host_port("socket://127.0.0.1:4001") == ("127.0.0.1", 4001)
    assert parse_host_port("tcp://localhost:9") == ("localhost", 9)
    with pytest.raises(ServobusError):
        parse_host_port("socket://127.0.0.1")


async def test_tcp_stream_round_trip_trace_and_close() -> None:
    async with echo_server() as (host, port):
        stream = await TcpStream.connect(host, port)
        assert isinstance(stream, ByteStream)
        rec = TraceRecorder()
        stream.add_trace(rec)
        await stream.write(b"\x01\x89\x80\x8a")
        assert await read_exactly(stream, 4) == b"\x01\x89\x80\x8a"
        assert rec.events[0].direction is Direction.TX
        await stream.close()
        await stream.close()  # idempotent
        with pytest.raises(ConnectionError):
            await stream.read()


async def test_tcp_stream_refused_is_a_servobus_error() -> None:
    async with echo_server() as (host, port):
        pass  # closed again: the port is free now
    with pytest.raises(ServobusError):
        await TcpStream.connect(host, port, timeout=2)


async def test_tcp_stream_sees_peer_hangup() -> None:
    async def hang_up(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.close()

    server = await asyncio.start_server(hang_up, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    stream = await TcpStream.connect("127.0.0.1", port)
    with pytest.raises(ConnectionError):
        await asyncio.wait_for(stream.read(), 2)
    await stream.close()
    server.close()
    await server.wait_closed()


async def test_serial_stream_loop_url() -> None:
    stream = await SerialStream.open("loop://", baud=38400)
    try:
        rec = TraceRecorder()
        stream.add_trace(rec)
        await stream.write(b"\x05\x86\x80\x8b")
        assert await read_exactly(stream, 4) == b"\x05\x86\x80\x8b"
        assert {e.direction for e in rec.events} == {Direction.TX, Direction.RX}
    finally:
        await stream.close()


async def test_serial_stream_socket_url_and_clean_shutdown() -> None:
    async with echo_server() as (host, port):
        stream = await SerialStream.open(f"socket://{host}:{port}", baud=38400)
        await stream.write(b"abc")
        assert await read_exactly(stream, 3) == b"abc"
        stream.discard_input()
        pending = asyncio.ensure_future(stream.read())
        # The read waits in pyserial's reader thread; nothing tells when it is blocked there
        # (a close before that must fail it just the same).
        await asyncio.sleep(0.01)  # see above
        await stream.close()
        with pytest.raises(ConnectionError):
            await asyncio.wait_for(pending, 2)
    reader_threads = [t for t in threading.enumerate() if t.name.startswith("serial-rx")]
    assert not reader_threads  # the reader thread was joined


async def test_serial_stream_bad_port_is_a_servobus_error() -> None:
    with pytest.raises(ServobusError):
        await SerialStream.open("/dev/servobus-no-such-port", baud=38400)
