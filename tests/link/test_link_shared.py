"""What the clients share lives once in servobus.link (issue 19): one StreamStats, one
can_spec for both CAN protocols, one CAN client base; the old axis/ paths are gone (issue 31)."""

from __future__ import annotations

import importlib

import pytest

from servobus.axis.url import can_spec, parse_url
from servobus.errors import ArgumentRangeError
from servobus.link import stats
from servobus.link.can import CanClient
from servobus.protocols.dyncan.client import AsyncDynCanClient
from servobus.protocols.dyncan.client import StreamStats as DynCanStreamStats
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.easycan.sync import StreamStats as EasyCanStreamStats


def test_one_stream_stats_for_both_streams() -> None:
    assert DynCanStreamStats is EasyCanStreamStats is stats.StreamStats
    s = stats.StreamStats(cycles=3, late_cycles=1)
    assert (s.cycles, s.late_cycles) == (3, 1)
    assert not hasattr(s, "ticks")  # DYN CAN's earlier names went with issue 31


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



@pytest.mark.parametrize("old", ["servobus.axis.transaction", "servobus.axis.late_replies",
                                 "servobus.axis.eeprom_guard"])
def test_the_one_release_aliases_are_gone(old: str) -> None:
    """Issue 31: the link modules are imported from servobus.link only."""
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
