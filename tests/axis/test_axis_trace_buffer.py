"""AsyncAxis.trace_buffer(): the virtual drives' 4 kHz trace on every sim:// protocol."""

from __future__ import annotations

import asyncio
import time

import pytest
from rig import wait_until_async

from servobus import connect_async
from servobus.axis.capture import STATUS_BITS, Capture, status_bits
from servobus.errors import NotSupported
from servobus.sim.core.capture import IDLE_STOP_S, SimCapture
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.trace import DriveTrace

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("url", ["sim://dyn232?ids=1,2&fast=1", "sim://dyncan?ids=1,2&fast=1",
                                 # YZ-AIM: several motors whose cores all have id 0 (issue 17.2)
                                 "sim://easycan?ids=1,2&fast=1", "sim://modbus?ids=1,2&fast=1"])
async def test_trace_of_a_move_in_axis_units_with_continuous_times(url: str) -> None:
    axis = await connect_async(url, drive_id=1)
    other = await axis.sibling(2)
    try:
        t_asked = time.monotonic()
        first = await axis.trace_buffer()  # starts the recording
        t_got = time.monotonic()
        assert first.rate_hz == 4000.0 and first.counts_per_rev == axis.counts_per_rev
        await axis.move_by(axis.revs(0.5))
        t_start = time.monotonic()
        # Read the trace as a host program would, chunk after chunk, until the move is over:
        # every chunk follows the previous one without a gap, whatever the machine's pace.
        chunks: list[Capture] = []
        def over() -> bool:  # the newest chunk is at the target, standing still
            last = chunks[-1] if chunks else first
            return bool(last.count) and abs(last.signals["position"][-1] - axis.revs(0.5)) < 50 \
                and max(abs(v) for v in last.signals["speed"]) < 1

        while not over():
            assert time.monotonic() - t_start < 30, "the move did not end"
            await asyncio.sleep(0.05)  # the host's polling period; the drive records meanwhile
            t_asked = time.monotonic()
            chunk = await axis.trace_buffer()
            t_got = time.monotonic()
            assert chunk.lost == 0
            previous = chunks[-1] if chunks else first
            assert chunk.t0 == pytest.approx(previous.t0 + previous.count / 4000, abs=1e-9)
            if chunk.count:  # drive time on the host clock: its newest sample is from
                # about when the read was asked and answered. The drives follow the host's
                # clock a few ms behind, or ahead by a frame's wire time (a bus model may
                # advance them to a frame's arrival); 1 s of slack on the late side (a loaded
                # machine) still catches a trace on another time base (drive time starts at 0).
                newest = chunk.t0 + (chunk.count - 1) / 4000
                assert t_asked - 1.0 <= newest <= t_got + 0.05
            chunks.append(chunk)
        signals = {name: [v for c in chunks for v in c.signals[name]]
                   for name in ("position", "position_error", "status", "speed")}
        pos = signals["position"]
        assert pos[0] < 100 and abs(pos[-1] - axis.revs(0.5)) < 50  # the whole move
        assert max(abs(e) for e in signals["position_error"]) > 1
        moving = status_bits(True, True, False, False)
        assert moving in set(signals["status"])
        assert max(signals["speed"]) > 100

        async def trace_ends_at_the_position() -> bool:  # once the servo has settled
            newest = (await axis.trace_buffer()).signals["position"]
            return bool(newest) and newest[-1] == await axis.position()

        await wait_until_async(trace_ends_at_the_position, timeout=10, poll=0.05,
                               what="the trace's newest position is the axis position")
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
    source = SimCapture([DriveTrace(drive)])
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
    from servobus.sim.core import capture

    monkeypatch.setattr(capture, "CAPACITY", 1000)
    drive = VirtualDrive(1)
    source = SimCapture([DriveTrace(drive)])
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
