"""A DYN232M client call never hangs past its deadline: upper bounds that can fail.

Every reply is lost (dropped on the in-process cable, or addressed to a drive id nobody has),
so a read must raise DriveTimeout after exactly ``deadline x attempts``: never before it (it
did wait for every attempt) and at most ``dyn232_rig.MARGIN_S`` (40 ms) after it: small
enough to catch a deadline that fires 50 ms late, robust on a loaded machine because a run
that overran is repeated and only the fastest one has to fit (scheduler noise only ever
makes a run slower, a late timer is late every time). See ``assert_gives_up_on_time``.

The repeated runs read the same register again after a timeout, which would first wait for
the late reply the timed-out attempts still owe (``late_reply_s``, the late-reply drain):
these tests turn the drain off (``late_reply_s=0``) to time the attempts alone; the drain's
own bound is timed in tests/link/test_link_abuse_stale.py.
"""

from __future__ import annotations

import time

import pytest
from dyn232_rig import PATHS, REPEATS, assert_gives_up_on_time, check_window, fail_late, rig

from servobus.axis import connect, connect_async
from servobus.errors import DriveTimeout
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.client import DEFAULT_TURNAROUND_S, AsyncDyn232Client
from servobus.transport.base import Direction
from servobus.transport.pair import Fault, open_pair

pytestmark = pytest.mark.timeout(30)

DEADLINE_S = 0.3
ABSENT_ID = 9  # no drive has it: its requests get silence
SIM_ONE_DRIVE = "sim://dyn2?fast=1&ids=0"  # one virtual drive, id 0 (not ABSENT_ID)
NO_DRAIN = 0.0  # late_reply_s: no late-reply drain between the repeated runs
STATUS_REQUEST_LEN = len(c.encode(0, DmmFunction.READ_DRIVE_STATUS))
#: 8N1: start bit + 8 data bits + stop bit per byte (the manual's 38400 8N1 line).
BITS_PER_BYTE = 1 + 8 + 1
#: Documented in servobus.protocols.dyn232.client: "turnaround_s (default 25 ms ...)".
DOCUMENTED_TURNAROUND_S = 0.025


def wire_time(n_bytes: int, baud: int) -> float:
    return n_bytes * BITS_PER_BYTE / baud


# ---------------------------------------------------------------------- deadline values
def test_documented_turnaround_margin() -> None:
    assert DEFAULT_TURNAROUND_S == DOCUMENTED_TURNAROUND_S


@pytest.mark.parametrize("baud", [9600, 19200, 38400, 57600, 115200])
def test_default_deadline_is_wire_time_of_request_and_longest_reply_plus_turnaround(
        baud: int) -> None:
    host, _ = open_pair()
    client = AsyncDyn232Client(host, baud=baud, retries=2)
    for request_len in range(4, 8):  # DYN232M packets are 4..7 bytes
        expected = wire_time(request_len + 7, baud) + DOCUMENTED_TURNAROUND_S
        assert client.reply_deadline_s(request_len) == pytest.approx(expected, abs=1e-12)
        assert client.worst_case_s(request_len) == pytest.approx(3 * expected, abs=1e-12)
    slow = AsyncDyn232Client(host, baud=baud, turnaround_s=0.1)
    assert slow.reply_deadline_s(4) == pytest.approx(wire_time(11, baud) + 0.1, abs=1e-12)
    fixed = AsyncDyn232Client(host, baud=baud, timeout=DEADLINE_S)
    assert fixed.reply_deadline_s(4) == DEADLINE_S  # timeout= replaces the whole deadline


# ---------------------------------------------------------------------- deadlines kept
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("retries", [0, 2])
async def test_explicit_timeout_raises_on_time(path: str, retries: int) -> None:
    async with rig(push=PATHS[path], timeout=DEADLINE_S, retries=retries,
                   late_reply_s=NO_DRAIN) as r:
        assert r.uses_push is PATHS[path]
        r.faults.set_rate(Direction.RX, Fault.DROP, 1.0)
        ax = r.axis(0)

        async def status_times_out() -> None:
            sent = r.wire.tx
            with pytest.raises(DriveTimeout):
                await ax.status()
            assert r.wire.tx - sent == STATUS_REQUEST_LEN * (retries + 1)  # every attempt

        await assert_gives_up_on_time(status_times_out, DEADLINE_S * (retries + 1))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("baud", [9600, 38400])
async def test_default_deadline_from_baud_rate_raises_on_time(path: str, baud: int) -> None:
    async with rig(push=PATHS[path], baud=baud, retries=2, late_reply_s=NO_DRAIN) as r:
        r.faults.set_rate(Direction.RX, Fault.DROP, 1.0)
        ax = r.axis(0)
        per_try = wire_time(STATUS_REQUEST_LEN + 7, baud) + DOCUMENTED_TURNAROUND_S

        async def status_times_out() -> None:
            with pytest.raises(DriveTimeout):
                await ax.status()

        await assert_gives_up_on_time(status_times_out, 3 * per_try)


@pytest.mark.parametrize("path", PATHS)
async def test_ping_timeout_is_one_attempt_on_time(path: str) -> None:
    async with rig(push=PATHS[path], retries=2, late_reply_s=NO_DRAIN) as r:  # no ping retry
        r.faults.set_rate(Direction.RX, Fault.DROP, 1.0)
        ax = r.axis(0)

        async def ping_is_false() -> None:
            assert await ax.ping(timeout=DEADLINE_S) is False

        await assert_gives_up_on_time(ping_is_false, DEADLINE_S)


@pytest.mark.parametrize("retries", [0, 2])
async def test_connect_timeout_and_retries_options_on_time(retries: int) -> None:
    ax = await connect_async(SIM_ONE_DRIVE, drive_id=ABSENT_ID, timeout=DEADLINE_S,
                             retries=retries, late_reply_s=NO_DRAIN)
    try:
        async def status_times_out() -> None:
            with pytest.raises(DriveTimeout):
                await ax.status()

        await assert_gives_up_on_time(status_times_out, DEADLINE_S * (retries + 1))
    finally:
        await ax.close()


def test_sync_connect_timeout_on_time() -> None:
    ax = connect(SIM_ONE_DRIVE, drive_id=ABSENT_ID, timeout=DEADLINE_S, retries=1,
                 late_reply_s=NO_DRAIN)
    try:
        expected = 2 * DEADLINE_S
        times: list[float] = []
        for _ in range(REPEATS):
            t0 = time.monotonic()
            with pytest.raises(DriveTimeout):
                ax.status()
            times.append(time.monotonic() - t0)
            if check_window(times, expected):
                return
        fail_late(times, expected)
    finally:
        ax.close()
