"""The production wheel (one timer for every cyclic producer) and the Class 1 frame packer
(no dataclasses per frame) against the codec's own encoder."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any, cast

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import FramingError
from servobus.protocols.enip.codec import io
from servobus.protocols.enip.production import EARLY_S, Producer, ProductionWheel


class Handle:
    def __init__(self, when: float, callback: Any) -> None:
        self.when, self.callback, self.cancelled = when, callback, False

    def cancel(self) -> None:
        self.cancelled = True


class FakeLoop:
    """time() and call_at() only: the test decides when the timer fires."""

    def __init__(self) -> None:
        self.now = 0.0
        self.handles: list[Handle] = []

    def time(self) -> float:
        return self.now

    def call_at(self, when: float, callback: Any) -> Handle:
        handle = Handle(when, callback)
        self.handles.append(handle)
        return handle

    def armed(self) -> Handle:
        live = [h for h in self.handles if not h.cancelled]
        assert len(live) >= 1
        return live[-1]

    def fire(self, late: float = 0.0) -> None:
        handle = self.armed()
        handle.cancelled = True
        self.now = handle.when + late
        handle.callback()


def wheel_with(*periods: float) -> tuple[FakeLoop, ProductionWheel, list[list[float]]]:
    loop = FakeLoop()
    wheel = ProductionWheel(cast(asyncio.AbstractEventLoop, loop))
    sent: list[list[float]] = []
    for period in periods:
        times: list[float] = []
        sent.append(times)
        wheel.add(Producer(period, 0.0, lambda t=times: t.append(loop.now)))
    return loop, wheel, sent


def test_one_timer_serves_every_producer_on_its_own_grid() -> None:
    loop, wheel, sent = wheel_with(0.005, 0.010)
    for _ in range(6):
        loop.fire()
    assert sent[0] == pytest.approx([0.0, 0.005, 0.010, 0.015, 0.020, 0.025])
    assert sent[1] == pytest.approx([0.0, 0.010, 0.020])
    assert len([h for h in loop.handles if not h.cancelled]) == 1  # one timer armed
    assert len(wheel) == 2


def test_a_late_wake_up_does_not_shift_the_grid() -> None:
    loop, _, sent = wheel_with(0.005)
    loop.fire()
    loop.fire(late=0.002)  # due 0.005, sent 0.007
    assert loop.armed().when == pytest.approx(0.010)  # still on the grid
    loop.fire()
    assert sent[0] == pytest.approx([0.0, 0.007, 0.010])


def test_falling_behind_by_more_than_a_period_restarts_the_grid() -> None:
    loop, wheel, sent = wheel_with(0.005)
    loop.fire()
    loop.fire(late=0.020)  # due 0.005, sent 0.025: no burst of four catch-up frames
    assert loop.armed().when == pytest.approx(0.030)
    assert wheel.late_restarts == 1 and len(sent[0]) == 2


def test_neighbours_due_within_early_s_leave_together_and_removal_is_lazy() -> None:
    loop = FakeLoop()
    wheel = ProductionWheel(cast(asyncio.AbstractEventLoop, loop))
    out: list[str] = []
    a = wheel.add(Producer(0.005, 0.0, lambda: out.append("a")))
    wheel.add(Producer(0.005, EARLY_S / 2, lambda: out.append("b")))
    loop.fire()
    assert out == ["a", "b"]
    wheel.remove(a)
    loop.fire()
    assert out == ["a", "b", "b"] and len(wheel) == 1


_u32 = st.integers(0, 0xFFFF_FFFF)
_i32 = st.integers(-(1 << 31), (1 << 31) - 1)


@given(_u32, _u32, st.integers(0, 0xFFFF), _i32, _i32, _i32, _u32)
def test_packer_bytes_equal_the_codec_s(conn: int, seq: int, count: int, pos: int, speed: int,
                                        torque: int, status: int) -> None:
    image = io.InputImage(pos, speed, torque, status)
    packed = bytes(io.input_packer(conn).pack(seq, count, pos, speed, torque, status))
    assert packed == io.input_frame(conn, seq, count, image)
    assert io.unpack_input(packed) == (conn, seq, count, image)
    out = bytes(io.output_packer(conn).pack(seq, count, io.RUN_BIT, status))
    assert out == io.output_frame(conn, seq, count, io.OutputImage(status))
    assert io.decode_frame(out) == io.IoFrame.decode(out)  # the adapter's fast path


@given(st.binary(min_size=22, max_size=22))
def test_decode_frame_equals_the_full_decoder(data: bytes) -> None:
    try:
        expected = io.IoFrame.decode(data)
    except FramingError:
        with pytest.raises(FramingError):
            io.decode_frame(data)
        return
    assert io.decode_frame(data) == expected


@given(st.binary(max_size=60))
def test_unpack_input_refuses_anything_else_typed(data: bytes) -> None:
    with contextlib.suppress(FramingError):
        io.unpack_input(data)


def test_unpack_input_checks_the_items() -> None:
    frame = bytearray(io.input_frame(1, 1, 1, io.InputImage(1, 2, 3, 4)))
    frame[2] = 0xB1  # the first item is no sequenced address any more
    with pytest.raises(FramingError):
        io.unpack_input(bytes(frame))
    with pytest.raises(FramingError):
        io.input_packer(1).pack(1, 1 << 16, 0, 0, 0, 0)  # count is 16 bits
