"""AsyncCanBus on a bus python-can serves from a thread (socketcand, pcan, ...): a burst of
frames reaches the loop in order, every frame once, with one wake per burst rather than per
frame; an error on the Notifier's thread fails the port (ConnectionLost) at once.

python-can's own ``virtual`` bus skips the Notifier (tests/transport/test_can_bus_virtual.py);
a subclass of it stands for a threaded bus here: the same queue, served the generic way."""

from __future__ import annotations

import asyncio
import itertools

import can
import pytest
from can.interfaces.virtual import VirtualBus

from servobus.errors import ConnectionLost
from servobus.transport.can_bus import AsyncCanBus

_channels = itertools.count()
pytestmark = pytest.mark.timeout(30)


class _ThreadedBus(VirtualBus):  # type: ignore[misc]
    """A virtual bus AsyncCanBus does not recognise: served by python-can's Notifier.

    Not can_rig's ScriptedCanPort: that one stands in for AsyncCanBus above the transport;
    here AsyncCanBus itself is under test, on a python-can bus."""


def _threaded_port(channel: str) -> AsyncCanBus:
    port = AsyncCanBus(_ThreadedBus(channel=channel))
    assert port._notifier is not None  # the path under test
    return port


async def test_a_burst_arrives_in_order_with_fewer_wakes_than_frames() -> None:
    channel = f"servobus-can-burst-{next(_channels)}"
    port = _threaded_port(channel)
    loop = asyncio.get_running_loop()
    wakes = 0
    threadsafe = loop.call_soon_threadsafe

    def counted(*args: object, **kwargs: object) -> asyncio.Handle:
        nonlocal wakes
        wakes += 1
        return threadsafe(*args, **kwargs)  # type: ignore[arg-type]

    loop.call_soon_threadsafe = counted  # type: ignore[method-assign]
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for i in range(200):  # sent from this (blocked) loop thread: they pile up
            sender.send(can.Message(arbitration_id=0x100 + i % 8, data=bytes([i % 256]),
                                    is_extended_id=False))
        got = []
        for _ in range(200):
            frame = await port.recv(timeout=5)
            assert frame is not None
            got.append(frame.data[0])
        assert got == [i % 256 for i in range(200)]
        assert wakes < 200  # the loop was woken per burst, not per frame
    finally:
        loop.call_soon_threadsafe = threadsafe  # type: ignore[method-assign]
        sender.shutdown()
        await port.close()


# python-can's Notifier thread re-raises the error and ends (as it does with loop=): expected
@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
async def test_an_error_on_the_notifier_thread_fails_the_port() -> None:
    port = _threaded_port(f"servobus-can-burst-{next(_channels)}")
    try:
        def broken(timeout: float | None) -> object:
            raise can.CanError("interface went down")

        port.bus._recv_internal = broken
        with pytest.raises(ConnectionLost):
            await port.recv(timeout=5)
    finally:
        await port.close()
