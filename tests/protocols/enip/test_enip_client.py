"""The asyncio explicit-messaging client: sessions, sender contexts, typed errors, deadlines,
read-only retries, late replies, a dead link (against the virtual DYN5 and a misbehaving
fake adapter)."""

from __future__ import annotations

import asyncio
import struct
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import pytest
from enip_rig import adapters
from rig import wait_until_async

from servobus.errors import ConnectionLost, DriveError, DriveTimeout, ProtocolError
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.client import AsyncEnipClient
from servobus.protocols.enip.codec.cip import MessageRouterRequest, MessageRouterResponse
from servobus.protocols.enip.codec.cpf import (
    CpfItem,
    ItemType,
    RRData,
    SockaddrInfo,
    UnconnectedMessage,
)
from servobus.protocols.enip.codec.encap import Command, EncapFramer, EncapPacket
from servobus.transport.base import Direction

pytestmark = pytest.mark.timeout(60)
PARAM = 0x0F


async def test_register_read_write_and_unregister() -> None:
    async with adapters() as fleet:
        server = fleet.servers[0]
        client = await AsyncEnipClient.connect(server.host, server.tcp_port)
        assert client.session and server.session_count == 1
        counter = [struct.unpack("<I", await client.get_attribute_single(PARAM, 0xFF, 1))[0]
                   for _ in range(3)]
        assert counter == [1, 2, 3]  # 6.1: the diagnostic counter counts each read
        await client.set_attribute_single(PARAM, 0x01, 1, struct.pack("<I", 42))
        assert await client.get_attribute_single(PARAM, 0x01, 1) == struct.pack("<I", 42)
        identity = await client.list_identity()
        assert identity.product_name == "DYN5ENIP" and identity.vendor_id == 0xABCD
        assert client.stats.sent == 7 and client.stats.replies == 7  # + RegisterSession
        assert client.stats.retries == 0
        await client.close()
        await wait_until_async(lambda: server.session_count == 0,  # UnregisterSession (or the
                               what="the session ended")  # close) ended it
        with pytest.raises(ConnectionLost):
            await client.get_attribute_single(PARAM, 0x01, 1)


async def test_refusals_are_drive_errors_with_the_cip_status() -> None:
    async with adapters() as fleet:
        s = fleet.servers[0]
        client = await AsyncEnipClient.connect(s.host, s.tcp_port)
        with pytest.raises(DriveError, match="05") as info:
            await client.set_attribute_single(PARAM, 0x01, 1, struct.pack("<I", 64))
        assert info.value.code == 0x05
        with pytest.raises(DriveError) as info:
            await client.set_attribute_single(PARAM, 0x01, 1, b"\x01\x00")  # 2 bytes: 05
        assert info.value.code == 0x05
        with pytest.raises(DriveError):
            await client.get_attribute_single(0x04, 100, 3)  # the Assembly object: 05
        assert client.stats.error_replies == 3 and client.stats.retries == 0  # no retry
        # the DYN5 quirks reach the client as values, not errors (4.1)
        unreadable = struct.pack("<I", dyn5.UNREADABLE)
        assert await client.get_attribute_single(PARAM, 0x15, 1) == unreadable  # write-only
        assert await client.get_attribute_single(PARAM, 0x10, 1) == unreadable  # missing
        await client.set_attribute_single(PARAM, 0x02, 1, bytes(4))  # read-only: no effect
        await client.close()


async def test_contexts_are_unique_and_traced() -> None:
    async with adapters() as fleet:
        s = fleet.servers[0]
        client = await AsyncEnipClient.connect(s.host, s.tcp_port)
        seen: list[tuple[Direction, object]] = []
        client.add_trace(lambda d, item, t: seen.append((d, item)))
        await client.get_attribute_single(PARAM, 0x1D, 1)
        assert [d for d, _ in seen] == [Direction.TX, Direction.RX]
        assert isinstance(seen[0][1], MessageRouterRequest)
        assert isinstance(seen[1][1], MessageRouterResponse) and seen[1][1].ok
        # concurrent calls on one session each get their own reply (one at a time)
        values = await asyncio.gather(*(client.get_attribute_single(PARAM, 0xFF, 1)
                                         for _ in range(20)))
        assert sorted(struct.unpack("<I", v)[0] for v in values) == list(range(1, 21))
        await client.close()


async def test_options_are_checked_before_connecting() -> None:
    for bad in ({"timeout": 0}, {"timeout": float("nan")}, {"retries": -1}, {"retries": 1.5},
                {"connect_timeout": -1}):
        with pytest.raises(ValueError):
            await AsyncEnipClient.connect("127.0.0.1", 1, **bad)  # type: ignore[arg-type]


# ---------------------------------------------------------------- a misbehaving adapter
Behaviour = Callable[[EncapPacket, asyncio.Transport, int], None]


class FakeAdapter(asyncio.Protocol):
    """Registers sessions, then lets ``behave`` decide what to do with each SendRRData."""

    requests: list[EncapPacket]

    def __init__(self, behave: Behaviour, log: list[EncapPacket]) -> None:
        self.behave = behave
        self.framer = EncapFramer()
        self.requests = log
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        assert self.transport is not None
        for pkt in self.framer.feed(data):
            assert isinstance(pkt, EncapPacket)
            if pkt.command == Command.REGISTER_SESSION:
                self.transport.write(pkt.reply(pkt.data, session=0x1234).encode())
            elif pkt.command == Command.SEND_RR_DATA:
                self.requests.append(pkt)
                self.behave(pkt, self.transport, len(self.requests))


def answer(pkt: EncapPacket, value: int = 7) -> bytes:
    request = MessageRouterRequest.decode(UnconnectedMessage.from_items(
        RRData.decode(pkt.data).items).message)
    response = MessageRouterResponse(request.service, data=struct.pack("<I", value))
    return pkt.reply(RRData(UnconnectedMessage(response.encode()).items()).encode()).encode()


@asynccontextmanager
async def fake(behave: Behaviour, timeout: float = 0.1
               ) -> AsyncIterator[tuple[AsyncEnipClient, list[EncapPacket]]]:
    log: list[EncapPacket] = []
    loop = asyncio.get_running_loop()
    server = await loop.create_server(lambda: FakeAdapter(behave, log), "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    client = await AsyncEnipClient.connect("127.0.0.1", port, timeout=timeout, retries=2)
    try:
        yield client, log
    finally:
        await client.close()
        server.close()


async def test_silence_is_a_drive_timeout_after_the_read_retries() -> None:
    async with fake(lambda pkt, t, n: None) as (client, log):
        start = time.monotonic()
        with pytest.raises(DriveTimeout, match="3 attempt"):
            await client.get_attribute_single(PARAM, 0x1D, 1)
        took = time.monotonic() - start
        assert len(log) == 3 and 0.29 <= took < 0.29 + 0.25
        assert len({p.context for p in log}) == 1  # the retries of one call: one context
        assert client.stats.timeouts == 3 and client.stats.retries == 2
        with pytest.raises(DriveTimeout):
            await client.get_attribute_single(PARAM, 0x1D, 1, retries=0)
        assert len(log) == 4 and log[3].context != log[0].context  # a new call: a new one


async def test_a_write_is_sent_once() -> None:
    async with fake(lambda pkt, t, n: None) as (client, log):
        with pytest.raises(DriveTimeout, match="not re-sent"):
            await client.set_attribute_single(PARAM, 0x17, 1, struct.pack("<i", 5000))
        assert len(log) == 1


async def test_a_late_reply_never_answers_a_later_request() -> None:
    loop = asyncio.get_running_loop()

    def behave(pkt: EncapPacket, transport: asyncio.Transport, n: int) -> None:
        if n == 1:  # the first reply comes after its deadline (0.1 s) and its retry's
            loop.call_later(0.15, transport.write, answer(pkt, 111))
        else:
            transport.write(answer(pkt, 200 + n))

    async with fake(behave) as (client, _log):
        first = await client.get_attribute_single(PARAM, 0x1D, 1)
        assert struct.unpack("<I", first)[0] == 202  # the retry's own reply
        await asyncio.sleep(0.1)  # the late 111 arrives now and is dropped
        second = await client.get_attribute_single(PARAM, 0x1D, 1)
        assert struct.unpack("<I", second)[0] == 203
        assert client.stats.late_replies == 1


async def test_a_closed_connection_fails_the_waiting_call_at_once_and_every_later_one() -> None:
    def behave(pkt: EncapPacket, transport: asyncio.Transport, n: int) -> None:
        transport.close()

    async with fake(behave, timeout=30.0) as (client, _):
        start = time.monotonic()
        with pytest.raises(ConnectionLost):
            await client.get_attribute_single(PARAM, 0x1D, 1)
        # Far inside the 30 s deadline: the close failed it, not the deadline (a bound a
        # loaded machine cannot reach; idle it takes a few ms).
        assert time.monotonic() - start < 15.0
        assert client.closed
        with pytest.raises(ConnectionLost):
            await client.set_attribute_single(PARAM, 0x01, 1, bytes(4))


async def test_a_bad_encapsulation_status_is_a_protocol_error() -> None:
    def behave(pkt: EncapPacket, transport: asyncio.Transport, n: int) -> None:
        transport.write(pkt.reply(status=0x0064).encode())

    async with fake(behave) as (client, _):
        with pytest.raises(ProtocolError, match="0x0064"):
            await client.get_attribute_single(PARAM, 0x1D, 1)


async def test_nothing_listening_is_a_drive_timeout_naming_the_address() -> None:
    with pytest.raises(DriveTimeout, match=r"127\.0\.0\.1:1"):
        await AsyncEnipClient.connect("127.0.0.1", 1, connect_timeout=0.5)


async def test_pipelined_requests_leave_together_and_each_gets_its_reply() -> None:
    async with adapters() as fleet:
        s = fleet.servers[0]
        client = await AsyncEnipClient.connect(s.host, s.tcp_port, max_in_flight=8)
        writes: list[int] = []
        client.stream.add_trace(lambda d, data, t: writes.append(len(data))
                                if d is Direction.TX else None)
        values = await asyncio.gather(*(client.get_attribute_single(PARAM, 0xFF, 1)
                                         for _ in range(16)))
        assert sorted(struct.unpack("<I", v)[0] for v in values) == list(range(1, 17))
        packet = 24 + 16 + 8  # header, plain SendRRData, Get_Attribute_Single request
        assert sum(writes) == 16 * packet and len(writes) < 16  # several per write
        await client.close()
    with pytest.raises(ValueError):
        await AsyncEnipClient.connect("127.0.0.1", 1, max_in_flight=0)


def _reply_with(pkt: EncapPacket, response: MessageRouterResponse, *,
                items_extra: tuple[CpfItem, ...] = ()) -> bytes:
    items = (*UnconnectedMessage(response.encode()).items(), *items_extra)
    return pkt.reply(RRData(items).encode()).encode()


@pytest.mark.parametrize(("response", "extra", "expect"), [
    # the plain shape, read at fixed offsets
    (MessageRouterResponse(0x0E, data=b"\x01\x02\x03\x04"), (), b"\x01\x02\x03\x04"),
    # additional status words on a success: the data follows them
    (MessageRouterResponse(0x0E, additional_status=(0x1234,), data=b"\x05\x06"), (),
     b"\x05\x06"),
    # a sockaddr item after the data item: the general decoder reads it
    (MessageRouterResponse(0x0E, data=b"\x07"),
     (SockaddrInfo(2222, "127.0.0.1").item(ItemType.SOCKADDR_T_O),), b"\x07"),
    (MessageRouterResponse(0x10, data=b"\x00"), (), ProtocolError),  # another service's
    (MessageRouterResponse(0x0E, general_status=0x05), (), DriveError),  # refused
])
async def test_a_read_reply_reads_as_the_general_decoder_says(
        response: MessageRouterResponse, extra: tuple[CpfItem, ...],
        expect: bytes | type[Exception]) -> None:
    """Reads take a fast path for the plain reply shape (issue 22): every other shape and
    every error still goes through the full decoder with its checks."""
    def behave(pkt: EncapPacket, transport: asyncio.Transport, n: int) -> None:
        transport.write(_reply_with(pkt, response, items_extra=extra))

    async with fake(behave) as (client, log):
        for _ in range(2):  # the second read reuses the packet parts built by the first
            if isinstance(expect, bytes):
                assert await client.get_attribute_single(PARAM, 0x1D, 1) == expect
            else:
                with pytest.raises(expect):
                    await client.get_attribute_single(PARAM, 0x1D, 1)
        assert len(log) == 2 and log[0].context != log[1].context
        assert all(p.session == 0x1234 for p in log)
        assert [RRData.decode(p.data).items for p in log] == [
            RRData.decode(log[0].data).items] * 2  # the same request, byte for byte
