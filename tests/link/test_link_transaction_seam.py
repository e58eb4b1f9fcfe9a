"""Both DMM clients on the one TransactionManager, seen through their public seam.

The manager's rules are tested on a scripted medium (test_link_transaction.py) and each
client's protocol rules in its own tests; here: both clients expose the manager and its one
stats class, refuse a request built by the other protocol before sending anything, and DYN
CAN's protocol-specific replies (Drive Error 0xFF in flight, alarm push) land in the shared
counters without a re-send.
"""

from __future__ import annotations

import pytest
from can_rig import Answer, ScriptedCanPort
from dyn232_rig import rig

from servobus.errors import ArgumentRangeError, DriveAlarm, DriveError
from servobus.link.transaction import TransactionStats
from servobus.protocols.dyn232 import commands as c232
from servobus.protocols.dyncan import codec as cc
from servobus.protocols.dyncan import commands as ccan
from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import AsyncDynCanClient

pytestmark = pytest.mark.timeout(20)


class ErrorDrive:
    """A script for ScriptedCanPort: one DYN CAN drive that answers every read with
    ``answer`` (a Drive Error code, or None: a normal reply of 0)."""

    def __init__(self, answer: int | None = None) -> None:
        self.answer = answer

    def __call__(self, arbitration_id: int, data: bytes) -> list[Answer]:
        request = cc.decode(arbitration_id, data)
        if not cc.expects_reply(request):
            return []
        if self.answer is None:
            frame = cc.reply(request.drive_id, cc.function_of(request.function), 0)
        else:
            frame = cc.Frame(request.drive_id, cc.Function.DRIVE_ERROR, bytes((self.answer,)))
        return [(frame.arbitration_id, frame.data)]


async def test_both_clients_share_the_manager_and_its_stats() -> None:
    port = ScriptedCanPort(ErrorDrive())
    can = AsyncDynCanClient(port)
    async with rig((0,)) as r:
        for client in (r.client, can):
            assert type(client.stats) is TransactionStats
            assert client.stats is client.transactions.stats
            assert client.late_replies is client.transactions.late_replies
            assert client.guard is client.transactions.guard
        await r.axis(0).position()  # one read (status() adds a speed read at rest)
        assert r.client.stats.sent == r.client.stats.replies == 1
    await can.close()


async def test_a_request_of_the_other_protocol_is_refused_before_sending() -> None:
    port = ScriptedCanPort(ErrorDrive())
    can = AsyncDynCanClient(port)
    async with rig((0,)) as r:
        with pytest.raises(ArgumentRangeError, match="not a DYN232M command"):
            await r.client.execute(ccan.make_read_status(1))
        assert r.client.stats.sent == 0 and r.wire.tx == 0
    with pytest.raises(ArgumentRangeError, match="not a DYN CAN command"):
        await can.execute(c232.make_read_status(1))
    assert port.sent == []
    await can.close()


async def test_drive_error_in_flight_ends_the_read_without_a_resend() -> None:
    port = ScriptedCanPort(ErrorDrive(cc.DriveErrorCode.INVALID_DATA))
    client = AsyncDynCanClient(port, retries=2)
    ax = DynCanAxis(client, 3)
    with pytest.raises(DriveError) as info:
        await ax.position()
    assert info.value.code == cc.DriveErrorCode.INVALID_DATA and info.value.drive_id == 3
    assert len(port.sent) == 1 and client.stats.retries == 0
    assert client.stats.error_replies == 1 and client.stats.timeouts == 0
    await client.close()


async def test_alarm_push_is_counted_and_raised_by_the_next_call() -> None:
    port = ScriptedCanPort(ErrorDrive())
    client = AsyncDynCanClient(port)
    ax = DynCanAxis(client, 3)
    alarm = cc.Frame(3, cc.Function.DRIVE_ERROR, bytes((cc.DriveErrorCode.ALARM,)))
    port.push(alarm.arbitration_id, alarm.data)
    assert client.stats.alarms == 1
    with pytest.raises(DriveAlarm):
        await ax.status()
    assert port.sent == []  # raised before sending
    assert await ax.position() == 0
    await client.close()
