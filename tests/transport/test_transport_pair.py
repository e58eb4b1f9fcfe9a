"""The in-process cable and its fault-injecting manipulator."""

from __future__ import annotations

import asyncio

import pytest

from servobus.transport.base import ByteStream, Direction, PushByteStream, set_receiver
from servobus.transport.pair import Fault, Manipulator, open_pair
from servobus.transport.trace import ByteCounter, TraceRecorder, format_event

pytestmark = pytest.mark.timeout(10)


async def read_exactly(stream: ByteStream, n: int, timeout: float = 1.0) -> bytes:
    out = b""
    async with asyncio.timeout(timeout):
        while len(out) < n:
            out += await stream.read(n - len(out))
    return out


async def test_pair_is_a_bytestream_both_ways() -> None:
    host, device = open_pair()
    assert isinstance(host, ByteStream) and isinstance(device, ByteStream)
    await host.write(b"\x01\x02")
    await device.write(b"\x83")
    assert await read_exactly(device, 2) == b"\x01\x02"
    assert await read_exactly(host, 1) == b"\x83"


async def test_drop_corrupt_duplicate_split_are_scripted_one_shots() -> None:
    m = Manipulator()
    host, device = open_pair(m)
    m.drop_next(direction=Direction.TX)
    await host.write(b"\x01\x81\x80\x82")  # dropped
    m.corrupt_next(direction=Direction.TX)
    await host.write(b"\x01\x81\x80\x82")  # last byte flipped
    m.duplicate_next(direction=Direction.TX)
    await host.write(b"\x02\x81")
    m.split_next(direction=Direction.TX, gap_s=0.01)
    await host.write(b"\x03\x84\x85\x86")
    got = await read_exactly(device, 4 + 4 + 4)
    assert got == b"\x01\x81\x80\x83" + b"\x02\x81" * 2 + b"\x03\x84\x85\x86"
    assert m.counts[Fault.DROP] == m.counts[Fault.CORRUPT] == 1
    assert m.counts[Fault.DUPLICATE] == m.counts[Fault.SPLIT] == 1


async def test_delay_keeps_wire_order() -> None:
    m = Manipulator()
    host, device = open_pair(m)
    m.delay_next(0.03, direction=Direction.RX)
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    await device.write(b"A")
    await device.write(b"B")  # not delayed itself, but may not overtake A
    assert await read_exactly(host, 2) == b"AB"
    assert loop.time() - t0 >= 0.025


async def test_random_faults_are_reproducible_with_a_seed() -> None:
    async def run(seed: int) -> bytes:
        m = Manipulator(seed=seed)
        m.set_rate(Direction.TX, Fault.DROP, 0.5)
        host, device = open_pair(m)
        for i in range(40):
            await host.write(bytes((i,)))
        await host.write(b"\xff")  # end marker (may itself be dropped: add a sure one)
        m.clear()
        await host.write(b"\xfe")
        out = b""
        while not out.endswith(b"\xfe"):
            out += await device.read()
        return out

    a, b = await run(7), await run(7)
    assert a == b and 0 < len(a) < 42


async def test_custom_hook_like_pymodbus_manipulator() -> None:
    seen: list[tuple[Direction, bytes]] = []

    def hook(direction: Direction, data: bytes) -> list[bytes]:
        seen.append((direction, data))
        return [data[::-1]]

    host, device = open_pair(Manipulator(custom=hook))
    await host.write(b"abc")
    assert await read_exactly(device, 3) == b"cba"
    assert seen == [(Direction.TX, b"abc")]


async def test_trace_sees_each_chunk_with_wire_direction() -> None:
    host, device = open_pair()
    rec, counter = TraceRecorder(), ByteCounter()
    host.add_trace(rec)
    host.add_trace(counter)
    await host.write(b"\x01\x89\x80\x8a")
    await device.write(b"\x01\x99\x80\x9a")
    await read_exactly(host, 4)
    assert [e.direction for e in rec.events] == [Direction.TX, Direction.RX]
    assert (counter.tx, counter.rx) == (4, 4)
    assert format_event(Direction.TX, b"\x01\x89").endswith("-> 01 89")


async def test_close_wakes_reader_on_both_ends() -> None:
    host, device = open_pair()
    reader = asyncio.ensure_future(device.read())
    await asyncio.sleep(0)  # one loop pass (a yield, not a wait): the read is pending
    await host.close()
    with pytest.raises(ConnectionError):
        await reader
    with pytest.raises(ConnectionError):
        await host.write(b"x")
    await host.close()  # idempotent


async def test_discard_input_drops_buffered_bytes() -> None:
    host, device = open_pair()
    await device.write(b"stale")
    host.discard_input()
    await device.write(b"new")
    assert await read_exactly(host, 3) == b"new"


async def test_pull_only_pair_has_no_push_capability() -> None:
    host, device = open_pair(push=False)
    assert not isinstance(host, PushByteStream) and not hasattr(host, "set_receiver")
    assert set_receiver(host, lambda data: None) is False
    await device.write(b"\x01")
    assert await read_exactly(host, 1) == b"\x01"


async def test_push_pair_pushes_keeps_earlier_bytes_and_hangs_up_once() -> None:
    host, device = open_pair()
    assert isinstance(host, PushByteStream)
    await device.write(b"early")
    got: list[bytes | None] = []
    assert set_receiver(host, got.append) is True
    await device.write(b"pushed")
    assert got == [b"pushed"]
    assert await read_exactly(host, 5) == b"early"  # buffered before the receiver came
    await device.close()  # the far end hangs up
    await host.close()
    assert got == [b"pushed", None]
