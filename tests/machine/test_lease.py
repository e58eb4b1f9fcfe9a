"""Leases (issue 27): where each target update goes, the ttl rules, one owner per axis, and a
lease that is not renewed ends by itself. The target arithmetic is pure and tested without a
drive; the rest on an in-process virtual machine."""

from __future__ import annotations

from pathlib import Path

import pytest
from machine_rig import write_machine
from rig import wait_until_async

from servobus.axis.types import StreamProfile
from servobus.errors import ArgumentRangeError, LimitError, OwnerError
from servobus.machine import open_machine_async
from servobus.machine.lease import STREAM_S, Lease, check_speed, check_ttl, lead


def make(speed: float, limit: float | None = None) -> Lease:
    return Lease("page 1", speed, accel=100.0, limit=limit, until=0.0)


def test_the_lead_is_the_stopping_distance_plus_one_update() -> None:
    assert lead(10.0, 100.0) == pytest.approx(10.0 * 10.0 / 200.0 + 10.0 * STREAM_S)
    assert lead(-10.0, 100.0) == lead(10.0, 100.0)


def test_the_first_target_is_one_lead_ahead_and_never_more() -> None:
    lease = make(10.0)
    first = lease.next_target(None, 0.0, 0.0)
    assert first == pytest.approx(lease.lead)
    # the motor fell behind (0.1 s without moving): the target still stays one lead ahead
    assert lease.next_target(first, 0.0, 0.1) == pytest.approx(lease.lead)
    # the motor follows: the target advances at the asked speed
    assert lease.next_target(first, 0.5, 0.05) == pytest.approx(first + 0.5)


def test_a_negative_speed_heads_down() -> None:
    lease = make(-10.0)
    assert lease.next_target(None, 3.0, 0.0) == pytest.approx(3.0 - lease.lead)


def test_the_target_never_passes_the_limit_it_heads_for() -> None:
    lease = make(10.0, limit=0.5)
    assert lease.next_target(None, 0.0, 0.0) == 0.5
    assert lease.at_limit
    lease = make(-10.0, limit=-0.2)
    assert lease.next_target(None, 0.0, 0.0) == -0.2
    assert lease.at_limit
    lease = make(10.0, limit=100.0)
    lease.next_target(None, 0.0, 0.0)
    assert not lease.at_limit


@pytest.mark.parametrize("ttl", [0, -1, 1.01, float("nan"), float("inf"), True, "0.5", None])
def test_a_ttl_is_above_0_and_at_most_a_second(ttl: object) -> None:
    with pytest.raises(ArgumentRangeError, match="ttl"):
        check_ttl(ttl)
    assert check_ttl(1) == 1.0


def test_a_speed_above_the_drive_profile_is_refused_in_the_axis_unit() -> None:
    profile = StreamProfile(max_rpm=600.0, accel_rpm_s=1000.0)
    with pytest.raises(ArgumentRangeError, match=r"axis x: 60 mm/s is above .* \(50 mm/s\)"):
        check_speed("x", 60.0, 720.0, profile, "mm/s", lambda rpm: rpm / 12)
    check_speed("x", 50.0, 600.0, profile, "mm/s", lambda rpm: rpm / 12)


LIMITED = ('[axes.c]\nurl = "sim://easycan?fast=1"\nid = 1\nunit = "deg"\n'
           "limits = [-720.0, 720.0]\n")


async def test_a_lease_not_renewed_ends_by_itself(tmp_path: Path) -> None:
    async with await open_machine_async(write_machine(tmp_path, LIMITED)) as m:
        c = m["c"]
        await c.jog(90.0, owner="page 1", ttl=0.2)
        lease = c.lease
        assert lease is not None and lease.owner == "page 1"
        await wait_until_async(lambda: _ended(c), timeout=10, what="the lease ends")
        assert lease.ended == "expired"
        await wait_until_async(lambda: _still(c), timeout=10, what="c at rest")


async def test_one_owner_per_axis_and_stop_always_wins(tmp_path: Path) -> None:
    async with await open_machine_async(write_machine(tmp_path, LIMITED)) as m:
        c = m["c"]
        await c.jog(90.0, owner="page 1", ttl=1.0)
        with pytest.raises(OwnerError, match="held by page 1") as info:
            await c.jog(-90.0, owner="page 2", ttl=1.0)
        assert info.value.owner == "page 1"
        await c.jog(120.0, owner="page 1", ttl=1.0)  # the owner renews and changes speed
        lease = c.lease
        assert lease is not None and lease.speed == 120.0
        await c.release("page 2")  # not the owner: nothing happens
        assert c.lease is lease
        await m.stop_all()
        assert c.lease is None and lease.ended == "stopped"
        await c.jog(-90.0, owner="page 2", ttl=1.0)  # free again
        await c.release("page 2")
        assert c.lease is None


async def test_a_jog_at_the_limit_is_refused(tmp_path: Path) -> None:
    text = LIMITED.replace("[-720.0, 720.0]", "[-720.0, 0.0]")
    async with await open_machine_async(write_machine(tmp_path, text)) as m:
        c = m["c"]
        with pytest.raises(LimitError, match="at soft limit"):
            await c.jog(90.0, owner="page 1")
        assert c.lease is None
        await c.jog(-90.0, owner="page 1", ttl=0.2)  # coming back inside is allowed
        await c.stop()


async def _ended(axis: object) -> bool:
    from servobus.machine import AsyncMachineAxis

    assert isinstance(axis, AsyncMachineAxis)
    return axis.lease is None


async def _still(axis: object) -> bool:
    from servobus.machine import AsyncMachineAxis

    assert isinstance(axis, AsyncMachineAxis)
    return abs(await axis.speed()) < 1.0


async def test_a_missed_reply_is_not_a_dropped_link() -> None:
    """Two reads that miss their deadline send no update and keep the lease; a lost link
    ends it at once; either way the axis is stopped once at the end (lease.stream)."""
    import time

    from servobus.errors import ConnectionLost, DriveTimeout
    from servobus.machine.lease import stream

    replies: list[object] = [DriveTimeout("late"), DriveTimeout("late"), 0.0, 0.1, 0.2]
    sent: list[float] = []
    stops: list[int] = []

    async def read() -> float:
        reply = replies.pop(0) if replies else 0.3
        if isinstance(reply, Exception):
            assert not sent, "no update may go out without a fresh position"
            raise reply
        assert isinstance(reply, float)
        return reply

    async def send(target: float) -> None:
        sent.append(target)

    async def stop() -> None:
        stops.append(1)

    lease = Lease("page 1", 1.0, accel=100.0, limit=None, until=time.monotonic() + 0.3)
    await stream(lease, "c", read, send, stop)
    assert lease.ended == "expired" and sent and stops == [1]

    async def lost() -> float:
        raise ConnectionLost("reset by peer")

    lease = Lease("page 1", 1.0, accel=100.0, limit=None, until=time.monotonic() + 10)
    await stream(lease, "c", lost, send, stop)
    assert lease.ended.startswith("failed") and stops == [1, 1]


def test_a_target_never_steps_back_on_a_late_position() -> None:
    """A position read that lags the motor would put the target behind it: the target
    holds instead (the axis never reverses inside a lease)."""
    lease = make(10.0)
    first = lease.next_target(None, 1.0, 0.0)
    assert lease.next_target(first, -5.0, 0.05) == first
    lease = make(-10.0)
    first = lease.next_target(None, -1.0, 0.0)
    assert lease.next_target(first, 5.0, 0.05) == first


async def test_a_renewal_above_the_drive_profile_is_refused(tmp_path: Path) -> None:
    """A renewal that changes the speed is checked as a new jog is: above the YZ-AIM's
    3000 rpm (18,000 deg/s) it is refused and the lease keeps its speed."""
    async with await open_machine_async(write_machine(tmp_path, LIMITED)) as m:
        c = m["c"]
        await c.jog(90.0, owner="page 1", ttl=1.0)
        with pytest.raises(ArgumentRangeError, match="max_speed allows"):
            await c.jog(20_000.0, owner="page 1", ttl=1.0)
        lease = c.lease
        assert lease is not None and lease.speed == 90.0
        await c.stop()
