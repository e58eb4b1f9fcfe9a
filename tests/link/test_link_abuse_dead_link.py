"""A dead link raises ConnectionLost on every protocol and transport (issue #8).

ConnectionLost is a ServobusError and a ConnectionError, so ``except ServobusError`` sees a
dead link, and a call that waits for a reply when the link dies fails at once, not at its
deadline (every read here has a 3 s deadline and must fail well under it). Every later call
fails the same way. Servers here are throw-away loopback listeners in the test itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest
from can_rig import ScriptedCanPort
from dyn232_rig import PATHS, rig
from dyncan_rig import harness

from servobus.axis import connect_async
from servobus.axis.base import AsyncAxis
from servobus.errors import ConnectionLost, DriveTimeout, ServobusError
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.protocols.dyncan.axis import DynCanAxis, open_can_axis
from servobus.protocols.dyncan.client import AsyncDynCanClient
from servobus.transport.base import TraceHook

pytestmark = pytest.mark.timeout(30)
DEADLINE_S = 3.0
AT_ONCE_S = 1.0  # a dead link is noticed in well under the deadline
ABSENT_ID = 9


async def fails_at_once(call: Awaitable[Any]) -> ConnectionLost:
    """``call`` raises ConnectionLost, also caught as ServobusError, before its deadline."""
    t0 = time.monotonic()
    with pytest.raises(ServobusError) as info:
        await call
    assert isinstance(info.value, ConnectionLost), repr(info.value)
    assert isinstance(info.value, ConnectionError)
    assert time.monotonic() - t0 < AT_ONCE_S
    return info.value


async def stays_dead(ax: AsyncAxis) -> None:
    """Reads, motion and settings after the loss all raise ConnectionLost at once."""
    for call in (ax.status(), ax.move_to(100), ax.write_param("main_gain", 30), ax.enable()):
        await fails_at_once(call)


def later(delay: float, action: Callable[[], Awaitable[Any]]) -> None:
    asyncio.get_running_loop().call_later(delay, lambda: asyncio.ensure_future(action()))


# ---------------------------------------------------------------------- DYN232M: the pair
@pytest.mark.parametrize("path", PATHS)
async def test_pair_cable_pulled_while_waiting(path: str) -> None:
    async with rig((0,), push=PATHS[path], timeout=DEADLINE_S) as r:
        ax = r.axis(ABSENT_ID)
        later(0.05, r.device.close)
        await fails_at_once(ax.status())
        await stays_dead(ax)
        await stays_dead(r.axis(0))


# ---------------------------------------------------------------------- DYN232M over TCP
@asynccontextmanager
async def tcp_peer(*, reset: bool) -> AsyncIterator[int]:
    """A loopback peer that takes the first request and then closes (FIN) or resets (RST)."""

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with contextlib.suppress(ConnectionError):
            await reader.read(64)
            await asyncio.sleep(0.05)  # a scripted peer's pause: the client is waiting by then
            if reset:
                sock = writer.get_extra_info("socket")
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()
        await server.wait_closed()


@pytest.mark.parametrize("transport", ["tcp", "pyserial"])
@pytest.mark.parametrize("reset", [False, True], ids=["fin", "rst"])
async def test_tcp_peer_gone_while_waiting(transport: str, reset: bool) -> None:
    async with tcp_peer(reset=reset) as port:
        ax = await connect_async(f"socket://127.0.0.1:{port}", drive_id=1, timeout=DEADLINE_S,
                                 transport=transport)
        try:
            await fails_at_once(ax.status())
            await stays_dead(ax)
        finally:
            await ax.close()


# ---------------------------------------------------------------------- DYN232M over sim://
async def test_sim_stream_closed_while_waiting() -> None:
    ax = await connect_async("sim://dyn2?fast=1&ids=0", drive_id=ABSENT_ID,
                             timeout=DEADLINE_S)
    try:
        assert isinstance(ax, Dyn232Axis)
        later(0.05, ax.client.stream.close)
        await fails_at_once(ax.status())
        await stays_dead(ax)
    finally:
        await ax.close()


# ---------------------------------------------------------------------- foreign streams
class BrokenStream:
    """A third-party ByteStream that fails with builtin OSErrors (no servobus types)."""

    def __init__(self, error: OSError) -> None:
        self.error = error

    async def write(self, data: bytes) -> None:
        raise self.error

    async def read(self, max_bytes: int = 4096) -> bytes:
        raise self.error

    def discard_input(self) -> None:
        pass

    async def close(self) -> None:
        pass

    def add_trace(self, hook: TraceHook) -> None:
        pass


@pytest.mark.parametrize("error", [BrokenPipeError(32, "Broken pipe"),
                                   ConnectionResetError(104, "reset by peer"),
                                   OSError(5, "Input/output error")], ids=repr)
async def test_builtin_errors_of_a_foreign_stream_become_connection_lost(error: OSError
                                                                          ) -> None:
    ax = Dyn232Axis(AsyncDyn232Client(BrokenStream(error), timeout=DEADLINE_S), 1)
    lost = await fails_at_once(ax.status())
    assert lost.__cause__ is error
    await stays_dead(ax)


# ---------------------------------------------------------------------- DYN CAN
async def test_can_bus_closed_while_waiting() -> None:
    async with harness(1, timeout=DEADLINE_S) as h:
        ax = h.axis(ABSENT_ID)
        later(0.05, h.client.port.close)
        await fails_at_once(ax.status())
        await stays_dead(ax)
        await fails_at_once(ax.position_direct(10))


async def test_builtin_errors_of_a_foreign_can_port_become_connection_lost() -> None:
    error = BrokenPipeError(32, "Broken pipe")
    client = AsyncDynCanClient(ScriptedCanPort(push_mode=False, send_error=error),
                              timeout=DEADLINE_S)
    ax = DynCanAxis(client, 1)
    try:
        lost = await fails_at_once(ax.status())
        assert lost.__cause__ is error
        await stays_dead(ax)
    finally:
        await client.close()


@asynccontextmanager
async def socketcand_peer() -> AsyncIterator[int]:
    """Just enough of socketcand for python-can's client: the handshake, then it hangs up
    after the first frame it is asked to send."""

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with contextlib.suppress(ConnectionError):
            writer.write(b"< hi >")
            await writer.drain()
            for _ in range(2):  # < open CHANNEL >, < rawmode >
                await reader.readuntil(b">")
                writer.write(b"< ok >")
                await writer.drain()
            await reader.readuntil(b">")  # the first < send ... >
            await asyncio.sleep(0.05)  # a scripted peer's pause: the client is waiting by then
            writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()
        await server.wait_closed()


async def test_socketcand_daemon_gone_while_waiting() -> None:
    async with socketcand_peer() as port:
        ax = await open_can_axis(f"socketcand:127.0.0.1:{port}", drive_id=1,
                                 timeout=DEADLINE_S)
        try:
            await fails_at_once(ax.status())
            await stays_dead(ax)
        finally:
            await ax.close()


async def test_a_timeout_is_not_a_lost_connection() -> None:
    """The conversion keeps DriveTimeout (a TimeoutError, hence an OSError) as it is."""
    async with harness(1, timeout=0.02, retries=0) as h:
        with pytest.raises(DriveTimeout):
            await h.axis(ABSENT_ID).status()
        assert await h.axis(1).read_id() == 1
