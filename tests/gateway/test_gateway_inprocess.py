"""The gateway in this process on a fake machine: link drops, alarm events, shutdown order,
and the rules of the sampler and of commands."""

from __future__ import annotations

import asyncio
import os
import signal

import pytest
from asyncua import Client, ua
from fake_machine import FakeMachine
from gateway_rig import axes_of, names, parameter
from rig import wait_until_async

from servobus.gateway.commands import Command, Commander, Refused
from servobus.gateway.opcua_server import OpcUaOptions
from servobus.gateway.sampler import (
    BAD_AFTER,
    OFFLINE,
    Health,
    RoundClock,
    Sample,
    Sampler,
    pause_after,
    typical_round,
)
from servobus.gateway.serve import GatewayOptions, serve_machine

OPTIONS = GatewayOptions(OpcUaOptions("opc.tcp://127.0.0.1:0"), rate_hz=50)


async def test_a_cut_link_reads_bad_alarms_are_events_and_sigterm_stops_first() -> None:
    """One gateway (serve_machine, as ``servobus serve`` runs it) for three checks: values
    carry BadCommunicationError while a link is cut and are Good when it is back; an alarm
    is an event; SIGTERM stops every axis before anything closes."""
    machine = FakeMachine()
    a0 = machine.axes["a0"]
    machine.axes["a1"].velocity = 3.0
    lines: list[str] = []
    ready = asyncio.Event()

    def say(line: str) -> None:
        lines.append(line)
        if "ready" in line:
            ready.set()

    serving = asyncio.create_task(serve_machine(machine, OPTIONS, say))  # type: ignore[arg-type]
    await asyncio.wait([serving, asyncio.create_task(ready.wait())],
                       return_when=asyncio.FIRST_COMPLETED)
    if serving.done():
        serving.result()
    endpoint = next(line.split()[3] for line in lines if line.startswith("servobus serve: opcua"))
    assert endpoint.startswith("opc.tcp://127.0.0.1:")
    events: list[object] = []

    class Handler:
        def event_notification(self, event: object) -> None:
            events.append(event)

    try:
        async with Client(endpoint) as client:
            n = await names(client)
            axes = await axes_of(client, "bench")
            position = await parameter(client, axes["a0"], "ActualPosition")
            moving = await parameter(client, axes["a0"], "Moving")

            async def reads(code: int, value: float | None = None) -> bool:
                dv = await position.read_data_value(raise_on_bad_status=False)
                return dv.StatusCode.value == code and (value is None or dv.Value.Value == value)

            await wait_until_async(lambda: reads(ua.StatusCodes.Good, 5.0), timeout=10,
                                   what="a0 at 5 mm")
            etype = await client.get_node(ua.ObjectIds.AlarmConditionType).get_child(
                [f"{n.servobus}:AxisAlarmConditionType"])
            subscription = await client.create_subscription(20, Handler())
            await subscription.subscribe_events(axes["a0"], etype)
            a0.cut = True
            await wait_until_async(lambda: reads(ua.StatusCodes.BadCommunicationError),
                                   timeout=10, what="Bad status while the link is cut")
            dv = await moving.read_data_value(raise_on_bad_status=False)
            assert dv.StatusCode.value == ua.StatusCodes.BadCommunicationError
            a0.pos = 7.0
            a0.cut = False
            await wait_until_async(lambda: reads(ua.StatusCodes.Good, 7.0), timeout=10,
                                   what="Good again when the link is back")
            a0.alarm = 2
            await wait_until_async(lambda: _true(any(getattr(e, "AlarmCode", 0) == 2
                                                     for e in events)),
                                   timeout=10, what="an alarm event")
            event = next(e for e in events if getattr(e, "AlarmCode", 0) == 2)
            assert (event.AxisName, event.AlarmText) == ("a0", "over current")  # type: ignore[attr-defined]
            code = await parameter(client, axes["a0"], "AlarmCode")
            await wait_until_async(lambda: _value_is(code, 2), timeout=10, what="AlarmCode 2")
            assert machine.log == []
    finally:
        if not serving.done():  # its loop handler takes the signal while it serves
            os.kill(os.getpid(), signal.SIGTERM)
        assert await serving == "SIGTERM"
    assert machine.log == ["stop_all", "close"]
    assert machine.axes["a1"].velocity == 0.0


async def test_commands_are_checked_before_the_axis_hears_of_them() -> None:
    machine = FakeMachine()
    commander = Commander(machine)  # type: ignore[arg-type]
    refusals = [
        (None, Command("a0", "move_relative", 1.0), "BadUserAccessDenied"),
        ("ann", Command("zz", "move_relative", 1.0), "BadNodeIdUnknown"),
        ("ann", Command("a0", "fly", 1.0), "BadMethodInvalid"),
        ("ann", Command("a0", "move_absolute", 150.0), "BadOutOfRange"),
        ("ann", Command("a0", "move_absolute", float("inf")), "BadInvalidArgument"),
        ("ann", Command("a0", "move_relative", 200.0), "BadOutOfRange"),  # the axis refuses
    ]
    for user, command, code in refusals:
        with pytest.raises(Refused) as refused:
            await commander.run(user, command, "test")
        assert refused.value.code == code, command
    machine.axes["a0"].cut = True
    with pytest.raises(Refused) as refused:
        await commander.run("ann", Command("a0", "move_to" if False else "set_speed", 2.0), "t")
    assert refused.value.code == "BadCommunicationError"
    machine.axes["a0"].online = False
    with pytest.raises(Refused) as refused:
        await commander.run("ann", Command("a0", "stop"), "test")
    assert refused.value.code == "BadCommunicationError"
    assert machine.log == []  # nothing reached an axis
    await commander.run("ann", Command("a1", "move_absolute", 12.5), "test")
    await commander.run("ann", Command("", "stop_all"), "test")
    assert machine.log == ["a1 move_to 12.5", "stop_all"]


def test_sampling_leaves_half_of_a_slow_link_for_commands() -> None:
    # a fast link: the configured period rules
    assert pause_after(0.02, 10.0, 10.001, 0.5) == pytest.approx(0.019)
    # a slow link: a round of 0.1 s is followed by 0.1 s free (duty 0.5)
    assert pause_after(0.02, 10.0, 10.1, 0.5) == pytest.approx(0.1)
    assert pause_after(0.02, 10.0, 10.1, 0.25) == pytest.approx(0.3)


def test_late_wake_ups_do_not_slow_the_rounds_down() -> None:
    # every round starts 4 ms after it was due (a loaded machine's wake-up) and takes 1 ms:
    # the rounds stay one period apart on average, the lateness is not added to each
    clock = RoundClock(0.02, 0.5, 0.0)
    start = 0.004
    for _ in range(50):
        start += clock.rest(start, start + 0.001) + 0.001 + 0.004
    assert start == pytest.approx(50 * 0.02 + 0.004)
    # a round later than a whole period moves the schedule on: the next is due when the
    # duty allows, the one after a period later, with no burst of rounds to catch up
    start += 0.1
    assert clock.rest(start, start + 0.001) == pytest.approx(0.001)
    start += 0.002
    assert clock.rest(start, start + 0.001) == pytest.approx(0.02 - 0.001)
    # and the duty still rules a slow link: 30 ms rounds, 30 ms free after each
    clock = RoundClock(0.02, 0.5, 0.0)
    assert [clock.rest(t, t + 0.03) for t in (0.0, 0.06)] == pytest.approx([0.03, 0.03])


def test_one_stretched_round_does_not_hold_the_next_back_by_its_length() -> None:
    average = None
    for _ in range(20):  # a fast link: rounds of 5 ms
        took, average = typical_round(0.005, average)
    took, average = typical_round(0.080, average)  # one round stretched to 80 ms
    assert took == pytest.approx(0.005 + 0.2 * 0.075)
    assert pause_after(0.02, 10.0, 10.08, 0.5, took) == pytest.approx(took)
    for _ in range(40):  # a steadily slow line settles on its own duration, as before
        took, average = typical_round(0.1, average)
    assert took == pytest.approx(0.1, rel=1e-3)
    took, _ = typical_round(0.002, average)  # a short round counts as itself
    assert took == 0.002


def test_axes_are_grouped_by_link() -> None:
    machine = FakeMachine(count=3)
    machine.axes["a2"].url = "fake://other"
    sampler = Sampler(machine, 10)  # type: ignore[arg-type]
    assert {u: [a.name for a in axes] for u, axes in sampler.links.items()} == {
        "fake://line": ["a0", "a1"], "fake://other": ["a2"]}
    with pytest.raises(ValueError):
        Sampler(machine, 0)  # type: ignore[arg-type]


async def _true(value: bool) -> bool:
    await asyncio.sleep(0)  # a coroutine predicate for wait_until_async: one yield, no wait
    return value


async def _value_is(node: object, value: object) -> bool:
    return bool(await node.read_value() == value)  # type: ignore[attr-defined]


def test_one_lost_answer_does_not_turn_an_axis_bad() -> None:
    machine = FakeMachine()
    sampler = Sampler(machine, 10)  # type: ignore[arg-type]
    seen: list[Sample] = []
    sampler.listeners.append(seen.append)
    good = Sample("a0", 1.0, True, position=5.0)
    lost = Sample("a0", 2.0, False, "no reply")
    sampler._publish(good)
    for _ in range(BAD_AFTER - 1):
        sampler._publish(lost)
    assert seen == [good] and sampler.latest["a0"] is good  # the last good one stands
    sampler._publish(lost)
    assert seen[-1] is lost and not sampler.latest["a0"].ok  # then Bad
    sampler._publish(good)
    assert sampler.latest["a0"] is good
    offline = Sample("a0", 3.0, False, OFFLINE, health=Health(online=False),
                     code="BadCommunicationError")
    sampler._publish(offline)
    assert sampler.latest["a0"] is offline  # offline is Bad at once
