"""A move has no reply; ``confirm=True`` verifies that the drive took it, never re-sending it.

Issue #8: a move sent while the drive is frozen reports success. Plain moves still do (the
host cannot know); the confirmed move reads where the drive is, sends the move once, then
watches status and position: DriveTimeout when the move does not show, and the motion
command is on the wire exactly once whatever happens. On the DYN232M rig (stepped virtual
time) and on DYN CAN virtual nodes.
"""

from __future__ import annotations

import pytest
from dyn232_rig import rig
from dyncan_rig import harness

from servobus.errors import ArgumentRangeError, DriveTimeout
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyncan import codec as cc
from servobus.transport.base import Direction
from servobus.transport.pair import Fault

pytestmark = pytest.mark.timeout(30)
H = c.HostFunction
MOVES = {int(DmmFunction.GO_ABSOLUTE_POS), int(DmmFunction.GO_RELATIVE_POS)}
TOLERANCE = U.onrange_to_counts(P.spec("on_range").default)
CONFIRM_S = 0.3


def is_move(data: bytes) -> bool:
    return len(data) >= 2 and data[1] & 0x1F in MOVES


def moves_sent(r: object) -> int:
    """Motion packets the host wrote (before any fault on the cable)."""
    return sum(1 for e in r.sent if is_move(e))  # type: ignore[attr-defined]


def record_host_writes(r: object) -> None:
    sent: list[bytes] = []
    r.sent = sent  # type: ignore[attr-defined]
    r.host.add_trace(lambda d, data, t: sent.append(data)  # type: ignore[attr-defined]
                     if d is Direction.TX else None)


async def test_confirmed_moves_return_once_the_drive_moves() -> None:
    async with rig((1,)) as r:
        record_host_writes(r)
        ax = r.axis(1)
        await ax.move_to(4000, confirm=True)  # counts
        assert r.drives[0].peek_status().motion_busy or abs(
            r.drives[0].position - 4000) <= TOLERANCE
        await ax.wait_idle(timeout=5)
        await ax.move_by(-2000, confirm=True, wait=True, timeout=5)
        assert abs(await ax.position() - 2000) <= TOLERANCE
        assert moves_sent(r) == 2


async def test_a_lost_move_raises_drive_timeout_and_is_not_resent() -> None:
    async with rig((1,)) as r:
        record_host_writes(r)
        ax = r.axis(1)
        before = r.drives[0].position
        # The cable eats the motion packet only: the drive stays where it is, reads work.
        r.faults.custom = lambda d, data: [] if d is Direction.TX and is_move(data) else [data]
        with pytest.raises(DriveTimeout, match="not re-sent"):
            await ax.move_to(2000, confirm=True, confirm_timeout=CONFIRM_S)
        assert moves_sent(r) == 1
        assert r.drives[0].position == before
        # Without confirm the same loss reports success: all a host can know is "sent".
        await ax.move_to(2000)
        assert moves_sent(r) == 2 and r.drives[0].position == before


class FreezeAtTheMove:
    """The drive freezes as the move arrives (as under SIGSTOP): no motion, no replies."""

    def __init__(self) -> None:
        self.frozen = False

    def __call__(self, direction: Direction, data: bytes) -> list[bytes]:
        if direction is Direction.TX and is_move(data):
            self.frozen = True
        return [] if self.frozen else [data]


async def test_a_frozen_drive_fails_the_confirmation_without_a_resend() -> None:
    async with rig((1,), timeout=0.02, retries=0) as r:
        record_host_writes(r)
        ax = r.axis(1)
        r.faults.custom = FreezeAtTheMove()
        with pytest.raises(DriveTimeout, match="reads failed"):
            await ax.move_by(300, confirm=True, confirm_timeout=CONFIRM_S)
        assert moves_sent(r) == 1


async def test_reads_before_the_send_fail_and_nothing_moves() -> None:
    async with rig((1,), timeout=0.02, retries=0) as r:
        record_host_writes(r)
        r.faults.set_rate(Direction.RX, Fault.DROP, 1.0)
        with pytest.raises(DriveTimeout):
            await r.axis(1).move_to(100, confirm=True)
        assert moves_sent(r) == 0


async def test_a_move_to_where_the_motor_is_counts_as_confirmed() -> None:
    async with rig((1,)) as r:
        record_host_writes(r)
        ax = r.axis(1)
        await ax.move_to(0, confirm=True, confirm_timeout=CONFIRM_S)
        assert moves_sent(r) == 1


async def test_confirm_checks_its_arguments_first() -> None:
    async with rig((1,)) as r:
        ax = r.axis(1)
        for bad in (None, 1.5, 33 * (c.VALUE_MAX + 1)):  # beyond any GEAR_NUM's reach
            with pytest.raises(ArgumentRangeError):
                await ax.move_to(bad, confirm=True)  # type: ignore[arg-type]
        assert r.wire.tx == 0  # not even the reads before the send


async def test_dyncan_confirmed_move_and_a_lost_one() -> None:
    async with harness(1, realtime=True) as h:  # the servo runs in wall-clock time
        ax = h.axis(1)
        sent: list[cc.Frame] = []
        h.client.add_trace(lambda d, item, t: sent.append(item)
                           if d is Direction.TX and isinstance(item, cc.Frame) else None)
        await ax.move_to(4000, confirm=True, wait=True, timeout=5)  # counts
        assert abs(await ax.position() - 4000) <= TOLERANCE
        network = h.network  # from now on the bus eats every motion frame
        real = network.handle
        network.handle = lambda frame: (  # type: ignore[method-assign]
            [] if frame.function in (DmmFunction.GO_ABSOLUTE_POS, DmmFunction.GO_RELATIVE_POS)
            else real(frame))
        with pytest.raises(DriveTimeout):
            await ax.move_by(1000, confirm=True, confirm_timeout=CONFIRM_S)
        moves = [f for f in sent if f.function in (DmmFunction.GO_ABSOLUTE_POS,
                                                   DmmFunction.GO_RELATIVE_POS)]
        assert len(moves) == 2
