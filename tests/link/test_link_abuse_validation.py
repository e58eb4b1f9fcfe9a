"""Every argument is checked before anything is sent, on every protocol (issue #8).

Motion and parameter arguments of the wrong type (None, bool, float, NaN, str, bytes) or out
of range, client options (``timeout`` NaN/0/negative/infinite, ``retries`` 1.5/None/-1) and
per-call knobs all raise ArgumentRangeError, and the wire stays silent: the DYN232M rig
counts the bytes the host writes, the CAN port here counts the frames it is given.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Coroutine
from typing import Any

import pytest
from can_rig import ScriptedCanPort
from dyn232_rig import rig

from servobus.axis import connect_async
from servobus.axis.base import AsyncAxis
from servobus.errors import ArgumentRangeError, DriveTimeout
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import AsyncDynCanClient
from servobus.transport.pair import open_pair

pytestmark = pytest.mark.timeout(30)
NAN = math.nan
#: Values no motion or parameter argument accepts (wrong type, or far out of any range).
BAD_VALUES: list[object] = [None, True, False, 1.5, NAN, math.inf, "10", b"\x01", [1],
                            2**40, -(2**40)]
BAD_SECONDS: list[object] = [NAN, math.inf, -math.inf, 0, 0.0, -1, -0.001, "1", None, True]
BAD_COUNTS: list[object] = [1.5, None, -1, True, "2", NAN]

Call = Callable[[AsyncAxis], Coroutine[Any, Any, Any]]


def motion_calls(value: Any) -> list[tuple[str, Call]]:
    return [
        ("move_to", lambda ax: ax.move_to(value)),
        ("move_by", lambda ax: ax.move_by(value)),
        ("move_to confirm", lambda ax: ax.move_to(value, confirm=True)),
        ("move_by wait", lambda ax: ax.move_by(value, wait=True, timeout=1)),
        ("turn", lambda ax: ax.turn(value)),
        ("square_wave", lambda ax: ax.square_wave(value)),  # type: ignore[attr-defined]
        ("sine_wave", lambda ax: ax.sine_wave(value)),  # type: ignore[attr-defined]
        ("wave_frequency", lambda ax: ax.wave_frequency(value)),  # type: ignore[attr-defined]
        ("write_param", lambda ax: ax.write_param("main_gain", value)),
        ("write_params", lambda ax: ax.write_params({"main_gain": value})),
        ("set_config", lambda ax: ax.set_config(value)),
        ("assign_id", lambda ax: ax.assign_id(value)),
    ]


BAD_NAMES: list[object] = [None, [], 5, b"main_gain", "no_such_param"]


def name_calls(name: Any) -> list[tuple[str, Call]]:
    calls: list[tuple[str, Call]] = [
        ("write_param", lambda ax: ax.write_param(name, 10)),
        ("read_param", lambda ax: ax.read_param(name)),
    ]
    if isinstance(name, str | bytes | int | None):  # hashable: can key a dict
        calls.append(("write_params", lambda ax: ax.write_params({name: 10})))
    return calls


def knob_calls() -> list[tuple[str, Call]]:
    calls: list[tuple[str, Call]] = []
    for bad in BAD_SECONDS:
        if bad is None:
            continue  # None means "the default" for the optional knobs
        calls += [
            (f"wait_idle timeout={bad!r}", lambda ax, b=bad: ax.wait_idle(timeout=b)),
            (f"ping timeout={bad!r}", lambda ax, b=bad: ax.ping(timeout=b)),
            (f"move_to wait timeout={bad!r}",
             lambda ax, b=bad: ax.move_to(10, wait=True, timeout=b)),
            (f"move_by confirm_timeout={bad!r}",
             lambda ax, b=bad: ax.move_by(10, confirm_timeout=b)),
        ]
    for bad in (NAN, -1, math.inf, "0"):
        calls.append((f"wait_idle poll={bad!r}", lambda ax, b=bad: ax.wait_idle(poll=b)))
    return calls


def all_calls() -> list[tuple[str, Call]]:
    calls = [(f"{n}({v!r})", c) for v in BAD_VALUES for n, c in motion_calls(v)]
    calls += [(f"{n}(name={v!r})", c) for v in BAD_NAMES for n, c in name_calls(v)]
    return calls + knob_calls()


# ---------------------------------------------------------------------- DYN232M
async def test_dyn232_axis_refuses_bad_arguments_before_sending() -> None:
    async with rig((1,)) as r:
        ax = r.axis(1)
        for label, call in all_calls():
            with pytest.raises(ArgumentRangeError):
                await call(ax)
            assert r.wire.tx == 0, f"{label} sent {r.wire.tx} byte(s)"
        assert await ax.read_id() == 1  # the line still works


async def test_dyn232_per_call_knobs_and_interpolation() -> None:
    async with rig((1,)) as r:
        ax = r.axis(1)
        status = r.client  # execute() takes retries/timeout per call
        from servobus.protocols.dyn232 import commands as cmds

        read = cmds.make_read_status(1)
        for bad in BAD_COUNTS:
            if bad is None:
                continue
            with pytest.raises(ArgumentRangeError):
                await status.execute(read, retries=bad)  # type: ignore[arg-type]
        for bad in BAD_SECONDS:
            if bad is None:
                continue
            with pytest.raises(ArgumentRangeError):
                await status.execute(read, timeout=bad)  # type: ignore[arg-type]
        for args in ([None, 0, 0, 10], [0, 0, 0, 1.5], [0, 0, 0, NAN], [True, 0, 0, 1]):
            with pytest.raises(ArgumentRangeError):
                await r.client.linear_line(*args)  # type: ignore[arg-type]
        for kw in ({"start": None, "end": (1, 1)}, {"start": (1, 1, 1), "end": (1, 1)},
                   {"start": (1, 1), "end": (NAN, 1)}, {"start": (1, 1), "end": (1, 1),
                                                         "plane": True},
                   {"start": (1, 1), "end": (1, 1), "feedrate": 0}):
            with pytest.raises(ArgumentRangeError):
                await r.client.circular_arc(**kw)  # type: ignore[arg-type]
        assert r.wire.tx == 0
        await ax.status()


@pytest.mark.parametrize("option", ["timeout", "turnaround_s", "query_interval_s",
                                    "late_reply_s", "retries", "baud"])
def test_dyn232_client_options_checked_at_construction(option: str) -> None:
    host, _ = open_pair()
    if option == "retries":
        bad_values = BAD_COUNTS
    elif option == "baud":
        bad_values = [0, -9600, 1.5, None, True, "38400"]
    else:
        bad_values = [b for b in BAD_SECONDS if b is not None]
        if option != "timeout":  # margins may be 0, not negative/NaN/inf
            bad_values = [b for b in bad_values if b not in (0, 0.0)]
    for bad in bad_values:
        with pytest.raises(ArgumentRangeError, match=option):
            AsyncDyn232Client(host, **{option: bad})


@pytest.mark.parametrize("options", [{"timeout": NAN}, {"timeout": 0}, {"retries": 1.5},
                                     {"retries": None}, {"late_reply_s": -1}])
async def test_connect_refuses_bad_options(options: dict[str, Any]) -> None:
    with pytest.raises(ArgumentRangeError):
        await connect_async("sim://dyn2?fast=1&ids=0", **options)


# ---------------------------------------------------------------------- DYN CAN
def can_only_calls(value: Any) -> list[tuple[str, Call]]:
    return [
        ("position_direct", lambda ax: ax.position_direct(value)),  # type: ignore[attr-defined]
        ("load_sync", lambda ax: ax.load_sync(value)),  # type: ignore[attr-defined]
        ("echo", lambda ax: ax.echo(value)),  # type: ignore[attr-defined]
    ]


async def test_dyncan_axis_refuses_bad_arguments_before_sending() -> None:
    port = ScriptedCanPort()  # nothing answers
    client = AsyncDynCanClient(port, timeout=0.02, retries=0)
    ax = DynCanAxis(client, 1)
    calls = all_calls() + [(f"{n}({v!r})", c) for v in BAD_VALUES
                           for n, c in can_only_calls(v)]
    calls += [(f"echo({v!r})", lambda ax, v=v: ax.echo(v))  # type: ignore[attr-defined]
              for v in ("abcd", b"abc", b"abcde", bytearray(3), 1234)]
    for label, call in calls:
        with pytest.raises(ArgumentRangeError):
            await call(ax)
        assert not port.sent, f"{label} sent {port.sent}"
    for bad in (NAN, 0, -1, "1"):
        with pytest.raises(ArgumentRangeError):
            await client.stream_position_direct({1: [1, 2]}, period=bad)  # type: ignore[arg-type]
    for targets in ({1: None}, {1: 1.5}, {None: 1}, {1: 2**40}):
        with pytest.raises(ArgumentRangeError):
            await client.sync_move(targets)  # type: ignore[arg-type]
    assert not port.sent
    with pytest.raises(DriveTimeout):  # four bytes in a bytearray are fine: sent, unanswered
        await ax.echo(bytearray(b"\x01\x02\x03\x04"))
    assert len(port.sent) == 1
    await client.close()


async def test_dyncan_move_none_sends_nothing() -> None:
    """The issue's case: DYN CAN move_to(None) used to send 0 and move the motor to 0."""
    port = ScriptedCanPort()  # nothing answers
    client = AsyncDynCanClient(port)
    ax = DynCanAxis(client, 1)
    for call in (ax.move_to(None), ax.move_by(None), ax.turn(None),  # type: ignore[arg-type]
                 ax.position_direct(None)):  # type: ignore[arg-type]
        with pytest.raises(ArgumentRangeError):
            await call
    assert not port.sent
    await client.close()


@pytest.mark.parametrize("option", ["timeout", "retries", "late_reply_s"])
async def test_dyncan_client_options_checked_at_construction(option: str) -> None:
    bad_values = BAD_COUNTS if option == "retries" else [b for b in BAD_SECONDS
                                                         if b is not None]
    if option == "late_reply_s":
        bad_values = [b for b in bad_values if b not in (0, 0.0)]
    for bad in bad_values:
        with pytest.raises(ArgumentRangeError, match=option):
            AsyncDynCanClient(ScriptedCanPort(), **{option: bad})
