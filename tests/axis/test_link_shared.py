"""What the clients share lives once in servobus.link (issue 19): one StreamStats, one
can_spec for both CAN protocols, one CAN client base, and the old import paths still work
for one release."""

from __future__ import annotations

import pytest

from servobus.axis.url import parse_url
from servobus.errors import ArgumentRangeError
from servobus.link import eeprom_guard, late_replies, stats, transaction
from servobus.link.can import CanClient, can_spec
from servobus.protocols.dyncan.client import AsyncDynCanClient
from servobus.protocols.dyncan.client import StreamStats as DynCanStreamStats
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.easycan.sync import StreamStats as EasyCanStreamStats


def test_one_stream_stats_for_both_streams() -> None:
    assert DynCanStreamStats is EasyCanStreamStats is stats.StreamStats
    s = stats.StreamStats(cycles=3, late_cycles=1)
    assert (s.ticks, s.late_ticks) == (3, 1)  # DYN CAN's earlier names, one release


def test_both_can_clients_share_the_base() -> None:
    for client in (AsyncDynCanClient, AsyncEasyCanClient):
        assert issubclass(client, CanClient)
        assert "_receive_loop" not in vars(client) and "close" not in vars(client)


@pytest.mark.parametrize("scheme", ["dyncan", "easycan"])
def test_can_spec_reads_every_can_url(scheme: str) -> None:
    assert can_spec(parse_url(f"{scheme}+pcan://PCAN_USBBUS1")) == ("pcan:PCAN_USBBUS1", {})
    assert can_spec(parse_url(f"{scheme}+socketcand://127.0.0.1:29536/can0")) == (
        "socketcand:127.0.0.1:29536", {"channel": "can0"})
    assert can_spec(parse_url(f"{scheme}+socketcand://127.0.0.1:29536")) == (
        "socketcand:127.0.0.1:29536", {})
    with pytest.raises(ArgumentRangeError, match=f"use {scheme}\\+<interface>://<channel>"):
        can_spec(parse_url(f"{scheme}://can0"))


def test_the_old_import_paths_still_work() -> None:
    from servobus.axis import eeprom_guard as old_guard
    from servobus.axis import late_replies as old_late
    from servobus.axis import transaction as old_transaction

    assert old_transaction.TransactionManager is transaction.TransactionManager
    assert old_transaction.TransactionStats is stats.TransactionStats
    assert old_transaction.check_call is transaction.check_call
    assert old_late.LateReplies is late_replies.LateReplies
    assert old_guard.EepromGuard is eeprom_guard.EepromGuard
    assert old_guard.EepromWearWarning is eeprom_guard.EepromWearWarning
