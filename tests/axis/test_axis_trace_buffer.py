"""AsyncAxis.trace_buffer(): the virtual drives' 4 kHz trace on every sim:// protocol."""

from __future__ import annotations

import asyncio
import time

import pytest

from servobus import connect_async
from servobus.axis.capture import STATUS_BITS, Capture, status_bits
from servobus.errors import NotSupported
from servobus.sim.capture import IDLE_STOP_S, SimCapture
from servobus.sim.dmm.drive import VirtualDrive

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("url", ["sim://dyn232?ids=1,2&fast=1", "sim://dyncan?ids=1,2&fast=1",
                                 # YZ-AIM: several motors whose cores all have id 0 (issue 17.2)
                                 "sim://easycan?ids=1,2&fast=1", "sim://modbus?ids=1,2&fast=1"])
async def test_trace_of_a_move_in_axis_units_with_continuous_times(url: str) -> None:
    axis = await connect_async(url, drive_id=1)
    other = await axis.sibling(2)
    try:
        first = await axis.trace_buffer()  # starts the recording
        assert first.rate_hz == 4000.0 and first.counts_per_rev == axis.counts_per_rev
        await axis.move_by(axis.revs(0.5))
        await asyncio.sleep(0.4)
        chunk = await axis.trace_buffer()
        t_read = time.monotonic()
        await asyncio.sleep(0.1)
        more = await axis.trace_buffer()
        assert 0.35 * 4000 <= chunk.count <= 0.6 * 4000
        assert more.t0 == pytest.approx(chunk.t0 + chunk.count / 4000, abs=1e-9)  # no gap
        newest = chunk.t0 + (chunk.count - 1) / 4000
        assert t_read - 0.02 <= newest <= t_read + 0.005  # drive time on the host clock
        pos = list(chunk.signals["position"]) + list(more.signals["position"])
        assert pos[0] < 100 and abs(pos[-1] - axis.revs(0.5)) < 50  # the whole move
        await asyncio.sleep(0.3)
        assert (await axis.trace_buffer()).signals["position"][-1] == await axis.position()
        assert max(abs(e) for e in chunk.signals["position_error"]) > 1
        moving = status_bits(True, True, False, False)
        assert moving in set(chunk.signals["status"])
        assert max(chunk.signals["speed"]) > 100
        assert (await other.trace_buffer()).count == 0  # the sibling records its own drive
    finally:
        await other.close()
        await axis.close()


async def test_a_drive_without_a_trace_says_so() -> None:
    axis = await connect_async("loop://", drive_id=1)
    try:
        with pytest.raises(NotSupported, match="poll"):
            await axis.trace_buffer()
    finally:
        await axis.close()


def test_recording_stops_when_nobody_reads_and_overflow_is_counted() -> None:
    drive = VirtualDrive(1)
    source = SimCapture([drive])
    assert source.read(1).count == 0 and drive.period_observer is not None
    drive.advance(1.0)
    cap = source.read(1)
    assert cap.count == 4000 and cap.lost == 0
    assert set(cap.signals) == {"position", "position_error", "speed", "current", "status"}
    drive.advance(IDLE_STOP_S + 0.5)  # nobody reads: the recording stops, periods batch again
    assert drive.period_observer is None
    late = source.read(1)  # what was recorded until it stopped
    assert late.count == IDLE_STOP_S * 4000 and late.t0 == pytest.approx(cap.t0 + 1.0)
    restarted = source.read(1)
    assert restarted.count == 0 and drive.period_observer is not None


def test_a_buffer_overflow_is_counted_as_lost(monkeypatch: pytest.MonkeyPatch) -> None:
    from servobus.sim import capture

    monkeypatch.setattr(capture, "CAPACITY", 1000)
    drive = VirtualDrive(1)
    source = SimCapture([drive])
    source.read(1)
    drive.advance(1.0)
    cap = source.read(1)
    assert cap.count == 1000 and cap.lost == 3000  # the newest 1000 kept
    assert cap.t0 == pytest.approx(source.read(1).t0 - 1000 / 4000, abs=1e-9)


def test_rescaled_positions_and_status_bits() -> None:
    from array import array

    cap = Capture(1.0, 4000.0, 65536, {"position": array("d", [65536.0]),
                                       "speed": array("d", [3.0])})
    half = cap.rescaled(32768)
    assert list(half.signals["position"]) == [32768.0] and list(half.signals["speed"]) == [3.0]
    assert cap.rescaled(65536) is cap
    assert STATUS_BITS == ("enabled", "moving", "in_position", "alarm")
    assert status_bits(True, False, True, True) == 0b1101
