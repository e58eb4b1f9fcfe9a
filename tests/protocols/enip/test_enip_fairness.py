"""``sim enip`` serves its TCP clients fairly (issue 17.5): a client flooding valid requests
without reading its replies delays a polite client by a few packets, not by its backlog, and
is not read while its replies are not drained (back-pressure). The order of service is
asserted; the polite client's reply time beside a flooder is a benchmark figure
(benchmarks/soak.py)."""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Callable

import enip_raw as raw
import pytest
from enip_rig import adapters
from rig import wait_until_async

from servobus.protocols.enip.codec.encap import EncapPacket
from servobus.protocols.enip.server import PACKETS_PER_TURN, EnipServer, _TcpClient

pytestmark = pytest.mark.timeout(60)
FLOOD = 400  # requests the flooder sends in one write
FLOODER, POLITE = b"flooder!", b"polite!!"


def read_request(session: int, context: bytes) -> bytes:
    mr = raw.mr_request(0x0E, bytes((0x20, 0x0F, 0x24, 1, 0x30, 0x01)))  # parameter 1
    return raw.packet(raw.SEND_RR_DATA, raw.rr_data(mr), session=session, context=context)


async def session(server: EnipServer) -> tuple[asyncio.StreamReader, asyncio.StreamWriter, int]:
    reader, writer = await asyncio.open_connection(server.host, server.tcp_port)
    writer.write(raw.packet(raw.REGISTER_SESSION, struct.pack("<HH", 1, 0)))
    head = raw.HEADER.unpack(await reader.readexactly(raw.HEADER.size))
    assert head[3] == 0
    await reader.readexactly(head[1])
    return reader, writer, head[2]


async def reply(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    head = raw.HEADER.unpack(await reader.readexactly(raw.HEADER.size))
    await reader.readexactly(head[1])
    return head[3], head[4]


async def until(predicate: Callable[[], object], timeout: float = 5.0) -> None:
    async def check() -> object:
        return predicate()
    await wait_until_async(check, timeout=timeout)


def record_order(server: EnipServer) -> tuple[list[bytes], asyncio.Event]:
    """The sender context of every SendRRData the server handles, in order, and an event
    set when the first one is handled."""
    order: list[bytes] = []
    first = asyncio.Event()
    handle = server.handle_packet

    def recording(item: object, client: _TcpClient | None) -> object:
        if isinstance(item, EncapPacket) and item.command == raw.SEND_RR_DATA:
            order.append(item.context)
            first.set()
        return handle(item, client)  # type: ignore[arg-type]

    server.handle_packet = recording  # type: ignore[assignment,method-assign]
    return order, first


async def test_a_polite_request_is_answered_before_the_flooders_next_few() -> None:
    """Before: the flooder's whole chunk was handled in one callback, the polite request
    waited behind all of it (2.7-20 s under a sustained flood)."""
    async with adapters() as fleet:
        server = fleet.servers[0]
        f_reader, f_writer, f_session = await session(server)
        p_reader, p_writer, p_session = await session(server)
        order, first = record_order(server)
        f_writer.write(read_request(f_session, FLOODER) * FLOOD)  # and never reads
        await first.wait()  # the server has the flood (a task wake-up: one or two turns)
        flooded_before = order.count(FLOODER)
        p_writer.write(read_request(p_session, POLITE))
        status, context = await reply(p_reader)
        assert (status, context) == (0, POLITE)
        at_polite = order.index(POLITE)
        flooded_meanwhile = at_polite - flooded_before
        assert at_polite < FLOOD // 2, "the flood was handled before the polite request"
        # The polite bytes are readable at the next poll (loopback): a turn or two of the
        # flooder's; the margin covers a late wake-up, never its backlog.
        assert flooded_meanwhile <= 4 * PACKETS_PER_TURN, order[flooded_before:at_polite + 1]
        await until(lambda: order.count(FLOODER) == FLOOD)  # the flooder is served too
        assert f_reader.at_eof() is False
        for w in (f_writer, p_writer):
            w.close()


async def test_a_client_that_does_not_read_is_not_read_and_others_are_served() -> None:
    """Back-pressure: the flooder's replies pile up, the server stops reading it (it is not
    dropped); the polite client keeps being answered meanwhile. Small socket buffers on both
    ends keep the flood that fills them small."""
    async with adapters() as fleet:
        server = fleet.servers[0]
        loop = asyncio.get_running_loop()
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        sock.setblocking(False)
        await loop.sock_connect(sock, (server.host, server.tcp_port))
        await loop.sock_sendall(sock, raw.packet(raw.REGISTER_SESSION, struct.pack("<HH", 1, 0)))
        answer = b""
        while len(answer) < raw.HEADER.size + 4:  # RegisterSession reply: header + 4 bytes
            answer += await loop.sock_recv(sock, raw.HEADER.size + 4 - len(answer))
        f_session = raw.HEADER.unpack_from(answer)[2]
        p_reader, p_writer, p_session = await session(server)
        flooder = next(c for c in server._clients if c.session == f_session)
        assert flooder.transport is not None
        server_side = flooder.transport.get_extra_info("socket")
        server_side.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        server_side.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        flood = asyncio.create_task(loop.sock_sendall(
            sock, read_request(f_session, FLOODER) * 40_000))  # never completes: not read
        try:
            await until(lambda: flooder._writing_paused, timeout=20.0)
            assert flooder._reading_paused
            for _ in range(5):
                p_writer.write(read_request(p_session, POLITE))
                assert await reply(p_reader) == (0, POLITE)
            assert flooder._writing_paused and flooder.transport is not None  # held, not dropped
            assert not flood.done()  # the server no longer reads the flooder
        finally:
            flood.cancel()
            sock.close()
            p_writer.close()
