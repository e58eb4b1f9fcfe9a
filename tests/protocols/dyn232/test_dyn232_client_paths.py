"""The client's two reception paths keep the same fault rules.

Push (``set_receiver``: TCP, ``sim://``) and pull (``read()``: pyserial) reach the client
differently (the stream calls its receive callback; the transaction manager's ``pull`` and
``flush`` hooks read and discard), so each fault test runs over a push-capable and a
pull-only in-process cable.
"""

from __future__ import annotations

import asyncio
import time

import pytest
from dyn232_rig import PATHS, assert_gives_up_on_time, rig

from servobus.errors import ChecksumError, DriveTimeout
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c
from servobus.transport.base import Direction, set_receiver
from servobus.transport.pair import Fault, open_pair

pytestmark = [pytest.mark.timeout(20), pytest.mark.parametrize("path", PATHS)]
H, D = c.HostFunction, c.DriveFunction
DEADLINE_S = 0.1


async def test_the_rig_really_takes_the_path(path: str) -> None:
    host, _ = open_pair(push=PATHS[path])
    assert set_receiver(host, None) is PATHS[path]
    async with rig(push=PATHS[path]) as r:
        assert r.uses_push is PATHS[path]
        assert await r.axis(0).read_id() == 0


async def test_corrupt_reply_is_retried_and_never_returned(path: str) -> None:
    async with rig(push=PATHS[path]) as r:
        ax = r.axis(0)
        await ax.write_param("main_gain", 77)
        r.faults.corrupt_next(n=1, direction=Direction.RX)
        assert await ax.read_param("main_gain") == 77
        assert r.client.stats.checksum_errors == 1 and r.client.stats.retries == 1
        assert any(isinstance(i, ChecksumError) for i in r.trace.items(Direction.RX))


async def test_every_reply_corrupt_raises_checksum_error(path: str) -> None:
    async with rig(push=PATHS[path], retries=2) as r:
        r.faults.corrupt_next(n=3, direction=Direction.RX)
        with pytest.raises(ChecksumError):
            await r.axis(0).position()
        assert r.client.stats.checksum_errors == 3
        assert r.wire.tx == 3 * len(c.encode(0, DF.GENERAL_READ, c.GeneralReadSelector.POSITION))


async def test_dropped_replies_are_retried(path: str) -> None:
    async with rig(push=PATHS[path]) as r:
        r.faults.drop_next(n=2, direction=Direction.RX)
        assert await r.axis(0).read_id() == 0
        assert r.client.stats.timeouts == 2 and r.client.stats.retries == 2


async def test_dropped_reply_raises_drive_timeout_within_deadline(path: str) -> None:
    # No late-reply drain: each repeated run must be the same call, not one that first waits
    # for the replies the previous run still owes (test_link_abuse_stale tests the drain).
    async with rig(push=PATHS[path], timeout=DEADLINE_S, retries=1, late_reply_s=0.0) as r:
        r.faults.set_rate(Direction.RX, Fault.DROP, 1.0)
        ax = r.axis(0)

        async def read_times_out() -> None:
            with pytest.raises(DriveTimeout):
                await ax.read_param("main_gain")

        await assert_gives_up_on_time(read_times_out, 2 * DEADLINE_S)


async def test_motion_is_sent_exactly_once(path: str) -> None:
    async with rig(push=PATHS[path], timeout=30.0) as r:  # a wait for a reply would show
        ax = r.axis(0)
        await ax.gear_num()  # counts -> command units: GEAR_NUM is read before the faults
        sent_before = r.client.stats.sent
        r.faults.drop_next(n=1, direction=Direction.TX)  # the move vanishes on the wire
        r.faults.set_rate(Direction.RX, Fault.DROP, 1.0)  # and nothing ever answers
        before = r.wire.tx
        t0 = time.monotonic()
        await ax.move_to(20000)  # counts: command 5000 at GEAR_NUM 4096
        await ax.turn(100)
        await ax.write_param("on_range", 20)
        await ax.set_origin()
        assert time.monotonic() - t0 < 15.0  # nothing waited for a reply (30 s deadline)
        sizes = [len(c.encode(0, f, v)) for f, v in ((DF.GO_ABSOLUTE_POS, 5000),
                 (DF.TURN_CONST_SPEED, 100), (H.SET_POS_ON_RANGE, 20), (DF.SET_ORIGIN, 0))]
        assert r.wire.tx - before == sum(sizes)  # one packet each, never re-sent
        assert r.client.stats.sent - sent_before == 4 and r.client.stats.retries == 0


async def test_stale_replies_before_the_request_are_skipped(path: str) -> None:
    async with rig((0,), push=PATHS[path]) as r:
        ax = r.axis(0)
        # A late reply from drive 0 and one from another id arrive before our request.
        await r.device.write(c.encode_reply(0, D.IS_ABS_POS32, 424242))
        await r.device.write(c.encode_reply(3, D.IS_DRIVE_ID, 3) + b"\x85\x99")
        await asyncio.sleep(0)  # one loop pass (a yield, not a wait): the bytes are delivered
        assert await ax.position() == r.drives[0].position != 424242


async def test_late_reply_of_a_timed_out_read_does_not_answer_the_next(path: str) -> None:
    async with rig((0,), push=PATHS[path], timeout=DEADLINE_S, retries=0) as r:
        ax = r.axis(0)
        await ax.write_param("main_gain", 77)
        await ax.write_param("speed_gain", 33)
        r.faults.delay_next(1.5 * DEADLINE_S, direction=Direction.RX)
        with pytest.raises(DriveTimeout):
            await ax.read_param("main_gain")
        # Its reply is still on the wire (and holds ours back): it must be skipped.
        assert await ax.read_param("speed_gain") == 33
        assert r.client.late_replies.late == 1  # recognised as the owed reply, dropped


async def test_garbage_and_foreign_packets_in_the_reply_window(path: str) -> None:
    async with rig((0,), push=PATHS[path]) as r:
        ax = r.axis(0)
        r.faults.custom = lambda d, data: (
            [b"\x91\x92" + c.encode_reply(7, D.IS_STATUS, 0) + data]
            if d is Direction.RX else [data]
        )
        assert await ax.read_id() == 0
        assert r.client.stats.unmatched >= 1


async def test_split_and_duplicated_replies_still_parse(path: str) -> None:
    async with rig((0,), push=PATHS[path], turnaround_s=0.2) as r:
        ax = r.axis(0)
        drive = r.drives[0]
        r.faults.split_next(direction=Direction.RX, gap_s=0.01)
        assert await ax.read_param("gear_num") == drive.get_param("gear_num")
        r.faults.duplicate_next(direction=Direction.RX)
        assert await ax.read_param("max_speed") == drive.get_param("max_speed")
        # the duplicate did not answer this one
        assert await ax.read_param("max_accel") == drive.get_param("max_accel")
