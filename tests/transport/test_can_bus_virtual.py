"""AsyncCanBus on python-can's ``virtual`` bus: no Notifier thread, the senders' ``put`` wakes
the loop (an eventfd from another thread, ``call_soon`` from the loop's own), once per burst;
every frame arrives once and in order; closing releases the wake-up and the channel."""

from __future__ import annotations

import asyncio
import itertools
import os
import threading

import can
import pytest
from can.interfaces.virtual import channels

from servobus.transport.can_bus import AsyncCanBus, _LoopQueue

_channels = itertools.count()
pytestmark = pytest.mark.timeout(30)


def _message(i: int) -> can.Message:
    return can.Message(arbitration_id=0x100 + i % 8, data=bytes([i % 256]),
                       is_extended_id=False)


async def _receive(port: AsyncCanBus, n: int) -> list[int]:
    got = []
    for _ in range(n):
        frame = await port.recv(timeout=5)
        assert frame is not None
        got.append(frame.data[0])
    return got


async def _open() -> tuple[str, AsyncCanBus, _LoopQueue]:
    """A port on a fresh channel, and the queue it put in the virtual bus's place."""
    channel = f"servobus-can-virtual-{next(_channels)}"
    port = await AsyncCanBus.open(f"virtual:{channel}")
    direct = port.bus.queue
    assert isinstance(direct, _LoopQueue)
    return channel, port, direct


async def test_no_notifier_thread_and_the_bus_queue_is_ours() -> None:
    _, port, direct = await _open()
    try:
        assert port._notifier is None
        assert any(q is direct for q in port.bus.channel)
    finally:
        await port.close()


async def test_a_burst_from_another_thread_arrives_in_order_with_fewer_wakes() -> None:
    channel, port, direct = await _open()
    drains = 0
    drain = direct._drain

    def counted() -> None:
        nonlocal drains
        drains += 1
        drain()

    direct._drain = counted  # type: ignore[method-assign]
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        thread = threading.Thread(
            target=lambda: [sender.send(_message(i)) for i in range(500)])
        thread.start()
        got = await _receive(port, 500)
        thread.join(5)
        assert got == [i % 256 for i in range(500)]
        assert 1 <= drains < 500  # woken per burst, not per frame
    finally:
        sender.shutdown()
        await port.close()


async def test_frames_sent_from_the_loops_own_thread_need_no_system_call() -> None:
    channel = f"servobus-can-virtual-{next(_channels)}"
    port = await AsyncCanBus.open(f"virtual:{channel}")
    sender = await AsyncCanBus.open(f"virtual:{channel}")  # a virtual drive on one loop
    loop = asyncio.get_running_loop()
    threadsafe = loop.call_soon_threadsafe
    writes = 0
    eventfd_write = os.eventfd_write

    def counted_write(fd: int, value: int) -> None:
        nonlocal writes
        writes += 1
        eventfd_write(fd, value)

    os.eventfd_write = counted_write  # type: ignore[assignment]

    def refuse(*args: object, **kwargs: object) -> asyncio.Handle:
        raise AssertionError("a wake through the self-pipe from the loop's own thread")

    loop.call_soon_threadsafe = refuse  # type: ignore[method-assign]
    try:
        for i in range(50):
            await sender.send(0x100 + i % 8, bytes([i]))
        assert await _receive(port, 50) == list(range(50))
        assert writes == 0
    finally:
        os.eventfd_write = eventfd_write
        loop.call_soon_threadsafe = threadsafe  # type: ignore[method-assign]
        await sender.close()
        await port.close()


async def test_frames_queued_before_the_port_took_the_bus_are_kept() -> None:
    channel = f"servobus-can-virtual-{next(_channels)}"
    bus = can.Bus(interface="virtual", channel=channel)
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for i in range(3):
            sender.send(_message(i))
        port = AsyncCanBus(bus)
        try:
            assert await _receive(port, 3) == [0, 1, 2]
        finally:
            await port.close()
    finally:
        sender.shutdown()


async def test_a_bounded_queue_keeps_its_size_and_unblocks_a_waiting_sender() -> None:
    channel = f"servobus-can-virtual-{next(_channels)}"
    bus = can.Bus(interface="virtual", channel=channel, rx_queue_size=4)
    port = AsyncCanBus(bus)
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        assert port.bus.queue.maxsize == 4
        thread = threading.Thread(
            target=lambda: [sender.send(_message(i), timeout=5) for i in range(40)])
        thread.start()
        assert await _receive(port, 40) == list(range(40))
        thread.join(5)
        assert not thread.is_alive()
    finally:
        sender.shutdown()
        await port.close()


async def test_close_releases_the_wake_up_and_the_channel() -> None:
    channel, port, direct = await _open()
    assert direct._efd >= 0 and direct._release.alive
    await port.close()
    assert direct._efd == -1
    assert not direct._release.alive  # os.close ran, once
    assert channel not in channels


async def test_a_bus_the_port_does_not_own_gets_its_own_queue_back_on_close() -> None:
    channel = f"servobus-can-virtual-{next(_channels)}"
    bus = can.Bus(interface="virtual", channel=channel)
    own_queue = bus.queue
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        port = AsyncCanBus(bus, owns_bus=False)
        assert bus.queue is not own_queue
        await port.close()
        assert bus.queue is own_queue and any(q is own_queue for q in bus.channel)
        sender.send(_message(7))
        msg = bus.recv(5)  # the user's bus works as python-can made it
        assert msg is not None and msg.data[0] == 7
    finally:
        sender.shutdown()
        bus.shutdown()
