"""Every opener checks every argument before a transport opens (issue 17.6).

A contract over every scheme the registry knows: bad options (NaN/inf/negative/zero
deadlines, bad counts, bad types, unknown names) and bad ids are refused with
ArgumentRangeError, and the transport entry points - patched to fail the test - are never
called. A positive control proves each scheme's valid call does reach the patched entry
point, so the contract cannot pass by missing the real one.
"""

from __future__ import annotations

import asyncio
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from servobus.axis import registry
from servobus.axis.connect import connect, connect_async
from servobus.axis.url import parse_url
from servobus.errors import ArgumentRangeError
from servobus.protocols.enip.client import AsyncEnipClient
from servobus.transport.can_bus import AsyncCanBus
from servobus.transport.serial_stream import SerialStream
from servobus.transport.tcp_stream import TcpStream

pytestmark = pytest.mark.timeout(60)

#: One URL per registered scheme, pointing where nothing listens. A scheme added to the
#: registry without a URL here fails test_every_registered_scheme_is_covered.
URLS: dict[str, str] = {
    "": "/dev/servobus-no-such-port",
    "dyn232": "dyn232+socket://127.0.0.1:1",
    "socket": "socket://127.0.0.1:1",
    "tcp": "tcp://127.0.0.1:1",
    "loop": "loop://",
    "rfc2217": "rfc2217://127.0.0.1:1",
    "spy": "spy://127.0.0.1:1",
    "alt": "alt:///dev/servobus-no-such-port",
    "hwgrep": "hwgrep://servobus-no-such-port",
    "cp2110": "cp2110://0001:0002:00",
    "dyncan": "dyncan+socketcand://127.0.0.1:1/can0",
    "easycan": "easycan+socketcand://127.0.0.1:1/can0",
    "enip": "enip://127.0.0.1:1",
    "modbus": "modbus+socket://127.0.0.1:1",
}
SIM_KINDS = sorted(registry.provided("SIM"))
NAN, INF = math.nan, math.inf
UNKNOWN = "frobnicate"


class Opened(Exception):
    """A transport entry point was called."""


@pytest.fixture
def no_transport(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Every way a real opener reaches the outside world raises Opened (and is logged)."""
    calls: list[str] = []

    def refuse(what: str) -> Any:
        async def opened(*args: object, **kwargs: object) -> None:
            calls.append(what)
            raise Opened(what)
        return opened

    monkeypatch.setattr(TcpStream, "open_url", refuse("tcp"))
    monkeypatch.setattr(SerialStream, "open", refuse("serial"))
    monkeypatch.setattr(AsyncCanBus, "open", refuse("can"))
    monkeypatch.setattr(AsyncEnipClient, "connect", refuse("enip"))
    monkeypatch.setattr(asyncio.BaseEventLoop, "create_connection", refuse("socket"))
    yield calls


def option_types(scheme: str, kind: str | None = None) -> dict[str, type]:
    """The option table of the opener the registry finds for a scheme (or a sim kind)."""
    target = registry.provided("SIM")[kind] if kind else registry.schemes()[scheme]
    module = sys.modules[registry.load(target).__module__]
    types = getattr(module, "SIM_OPTIONS" if kind else "OPTIONS")
    assert isinstance(types, dict) and types, target
    return types


def bad_calls(types: dict[str, type]) -> list[tuple[str, dict[str, Any]]]:
    """(query, keywords) pairs that must each be refused."""
    calls: list[tuple[str, dict[str, Any]]] = [
        ("", {UNKNOWN: 1}), (f"{UNKNOWN}=1", {}),
        ("", {"drive_id": -1}), ("", {"drive_id": True}), ("", {"drive_id": "1"}),
        ("", {"drive_id": 1.5}), ("", {"drive_id": 100_000}),
    ]
    for name, kind in types.items():
        if kind is float:
            calls += [("", {name: bad}) for bad in (NAN, INF, -INF, -1.0, "1", True)]
            if name != "timeout":  # timeout=None is the protocol's default
                calls.append(("", {name: None}))
            calls += [(f"{name}=nan", {}), (f"{name}=-inf", {}), (f"{name}=x", {})]
        elif kind is int:
            calls += [("", {name: bad}) for bad in (-1, 1.5, True, "2", None)]
            calls += [(f"{name}=x", {}), (f"{name}=1.5", {})]
        elif kind is str:
            calls += [("", {name: bad}) for bad in (5, b"x", None)]
        elif kind is bool:
            calls += [("", {name: bad}) for bad in (2, "yes", None)]
        else:  # objects: guards and callbacks
            calls += [("", {name: bad}) for bad in (5, "x")]
    if "timeout" in types:
        calls += [("", {"timeout": 0}), ("", {"timeout": -0.001})]
    return calls


def refused(url: str, query: str, keywords: dict[str, Any]) -> ArgumentRangeError:
    if query:
        url += ("&" if "?" in url else "?") + query
    drive_id = keywords.pop("drive_id", 1)
    with pytest.raises(ArgumentRangeError) as err:
        connect(url, drive_id=drive_id, **keywords)
    return err.value


def case_id(query: str, keywords: dict[str, Any]) -> str:
    return query or ",".join(f"{k}={v!r}" for k, v in keywords.items())


def test_every_registered_scheme_is_covered() -> None:
    assert set(URLS) == set(registry.schemes()) - {"sim"}
    assert SIM_KINDS  # sim:// has its kinds


def test_the_issue_call_is_refused_without_connecting(no_transport: list[str]) -> None:
    """Before: it tried to connect and reported the refused connection."""
    with pytest.raises(ArgumentRangeError, match="timeout"):
        connect("dyn232+socket://127.0.0.1:1", drive_id=1, timeout=float("nan"))
    assert no_transport == []


@pytest.mark.parametrize("scheme", sorted(URLS))
def test_bad_arguments_are_refused_before_the_transport_opens(
        scheme: str, no_transport: list[str]) -> None:
    types = option_types(scheme)
    failures = []
    for query, keywords in bad_calls(types):
        try:
            refused(URLS[scheme], query, dict(keywords))
        except BaseException as exc:  # collected: one report per scheme
            failures.append(f"{case_id(query, keywords)}: {type(exc).__name__}: {exc}")
    assert failures == [] and no_transport == [], "\n".join(failures)


@pytest.mark.parametrize("scheme", sorted(URLS))
def test_valid_arguments_do_reach_the_patched_transport(
        scheme: str, no_transport: list[str]) -> None:
    """The control: without it the contract above could pass by patching the wrong place."""
    with pytest.raises(Opened):
        connect(URLS[scheme], drive_id=1, timeout=0.5)
    assert len(no_transport) == 1


@pytest.mark.parametrize("kind", SIM_KINDS)
def test_sim_refuses_bad_arguments_before_it_starts_anything(kind: str, tmp_path: Path) -> None:
    """The in-process simulator's state file is the first thing it opens: never created."""
    state = tmp_path / "state.json"
    url = f"sim://{kind}?fast=1&state={state}"
    failures = []
    for query, keywords in bad_calls(option_types("sim", kind)):
        if "state" in keywords or query.startswith("state"):
            continue  # the URL names the state file already
        try:
            refused(url, query, dict(keywords))
        except BaseException as exc:  # collected: one report per kind
            failures.append(f"{case_id(query, keywords)}: {type(exc).__name__}: {exc}")
    assert failures == [], "\n".join(failures)
    assert not state.exists()


async def test_a_valid_sim_call_opens_its_state_file(tmp_path: Path) -> None:
    """The control of the test above: a valid call does create the state file."""
    state = tmp_path / "state.json"
    axis = await connect_async(f"sim://modbus?fast=1&state={state}", drive_id=1)
    await axis.close()
    assert state.exists() and parse_url(f"sim://modbus?state={state}").options
