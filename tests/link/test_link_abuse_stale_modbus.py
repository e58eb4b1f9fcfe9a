"""No stale read on Modbus RTU and EasyCan either (issue 17.7).

The issue: after a read whose replies were delayed (150 ms, timeouts in play) the next
position read returned the value from before a 4000-count move, once in 155 trials. The
cause: an attempt ended by the *caller* (``asyncio.timeout``, ``wait_for``, a sync call's
timeout, Ctrl-C) after its request had left owed nothing, so its late reply, arriving while
the next read of the same kind waited, was taken as that read's answer (RTU replies carry no
transaction id; neither do DYN232M's or DYN CAN's). The shared transaction manager now owes
that reply like one of a timed-out attempt, and the next read drains it first.

The sequence - a delayed reply, a timeout, the late reply arriving during the next read -
runs scripted on the fault-injecting pair, many rounds, on every reception path; then the
random profile of benchmarks.stale_reads on Modbus and EasyCan.
"""

from __future__ import annotations

import asyncio

import pytest
from dyn232_rig import PATHS

# benchmarks/ is a package of the repository (not installed): pytest's pythonpath has the root.
from benchmarks.stale_reads import (
    _Counter,
    _serve_dyn232,
    _serve_modbus,
    easycan_stale,
    modbus_stale,
)
from servobus.errors import DriveTimeout
from servobus.families.yzaim import registers as Y
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.protocols.modbus.axis import ModbusAxis
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.transport.base import Direction
from servobus.transport.pair import Manipulator, open_pair

pytestmark = pytest.mark.timeout(60)
ROUNDS = 12
DEADLINE_S = 0.12  # the client's deadline per attempt: longer than LATE_S
LATE_S = 0.03  # the first read's reply comes this late...
CUT_S = 0.01  # ...after its caller gave up (or its own deadline passed) at this time
NEXT_DELAY_S = 0.045  # the next read's reply is slow too: the late one arrives first
READS = 40
POSITION = Y.BY_NAME["absolute_position_low"].address
SERVERS = {"modbus": _serve_modbus, "dyn232": _serve_dyn232}


async def _first_read_ends(axis: ModbusAxis | Dyn232Axis, how: str) -> None:
    """A position read that ends before its (delayed) reply comes."""
    if how == "caller timeout":
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(CUT_S):
                await axis.position()
    else:  # the client's own deadline
        assert isinstance(axis, ModbusAxis)
        with pytest.raises(DriveTimeout):
            await axis.client.read(1, POSITION, 2, retries=0, timeout=CUT_S)


#: (protocol, how the first read ends); DYN232M's client-deadline path is
#: test_link_abuse_stale's.
CASES = [("modbus", "caller timeout"), ("modbus", "client deadline"),
         ("dyn232", "caller timeout")]


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize(("protocol", "how"), CASES)
async def test_a_late_reply_never_answers_the_next_read(protocol: str, how: str,
                                                        path: str) -> None:
    """Before (caller timeout): every round returned the previous read's value."""
    faults = Manipulator(seed=17)
    host, device = open_pair(faults, push=PATHS[path])
    counter = _Counter()
    server = asyncio.create_task(SERVERS[protocol](device, counter))
    axis: ModbusAxis | Dyn232Axis
    if protocol == "modbus":
        axis = ModbusAxis(AsyncModbusClient(host, timeout=DEADLINE_S), 1)
    else:
        axis = Dyn232Axis(AsyncDyn232Client(host, timeout=DEADLINE_S), 1)
    stale = []
    try:
        await axis.position()
        for _ in range(ROUNDS):
            faults.delay_next(CUT_S + LATE_S, direction=Direction.RX)  # the first read's
            faults.delay_next(NEXT_DELAY_S, direction=Direction.RX)  # the next read's
            await _first_read_ends(axis, how)
            start = counter.received
            value = await axis.position()
            if value < start:
                stale.append((value, start))
        assert stale == [], f"{len(stale)} of {ROUNDS} reads returned an older value: {stale}"
        late = axis.client.late_replies
        # Every round owed a reply; it came and was known (late), or was waited out (a caller
        # timeout before the request left still owes: conservative, it costs one wait).
        assert late.late + late.given_up >= ROUNDS and late.late >= ROUNDS // 2, late
    finally:
        await axis.client.close()
        await server


async def test_modbus_random_profile_gives_no_stale_value() -> None:
    after = await modbus_stale(READS)
    assert after.ok >= READS // 2 and after.late > 0, after
    assert after.stale == 0, after
    before = await modbus_stale(READS, late_reply_s=0.0)  # the harness does see stale values
    assert before.stale > 0, before


async def test_easycan_random_profile_gives_no_stale_value() -> None:
    after = await easycan_stale(READS)
    assert after.ok >= READS // 2 and after.late > 0, after
    assert after.stale == 0, after
    before = await easycan_stale(READS, late_reply_s=0.0)
    assert before.stale > 0, before
