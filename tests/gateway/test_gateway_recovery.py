"""Links that come back (issue 29), in this process on a fake machine whose links go down and
come back as the machine's recovery takes them: Bad values with their last good time, one
event per link change, the health variables and state fields, and Acknowledge / MQTT ack.
An independent asyncua client and a real Mosquitto broker are the peers."""

from __future__ import annotations

import asyncio
import json
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiomqtt
from asyncua import Client, Node, ua
from asyncua.ua.uaerrors import UaStatusCodeError
from fake_machine import FakeAxis, FakeMachine
from gateway_rig import (
    BROKER_USERS,
    PASSWORD,
    USER,
    axes_of,
    machine_node,
    mosquitto,
    names,
    parameter,
    user_client,
)
from rig import wait_until_async

import servobus
from servobus.gateway.commands import Commander
from servobus.gateway.link_events import REOPENED, LinkEvent, LinkWatch
from servobus.gateway.mqtt import MqttGateway, MqttOptions, link_json, state_json
from servobus.gateway.opcua_server import OpcUaOptions
from servobus.gateway.sampler import Health, Sample, Sampler
from servobus.gateway.serve import Gateway, GatewayOptions
from servobus.gateway.users import Users


def three_links() -> FakeMachine:
    """a0 and a1 on links of their own, a2 on a link that could not be opened at start."""
    machine = FakeMachine(count=3)
    machine.axes["a1"].url = "fake://other"
    machine.axes["a2"].url = "fake://late"
    machine.axes["a2"].drop("cannot open fake://late")
    return machine


async def start(machine: FakeMachine) -> Gateway:
    users = Users()
    users.add(USER, PASSWORD)
    gateway = Gateway(machine, GatewayOptions(  # type: ignore[arg-type]
        OpcUaOptions("opc.tcp://127.0.0.1:0", users=users), rate_hz=50))
    await gateway.start()
    return gateway


def count_rounds(gateway: Gateway, axis: str) -> Callable[[], int]:
    """How many samples of ``axis`` the sampler has published (one per round)."""
    seen = [0]

    def note(sample: Any) -> None:
        if sample.axis == axis:
            seen[0] += 1
    gateway.sampler.listeners.append(note)
    return lambda: seen[0]


async def dv(node: Node) -> ua.DataValue:
    return await node.read_data_value(raise_on_bad_status=False)


async def code_of(call: Any) -> str:
    """The name of the status code a method call answers (Good when it does not raise)."""
    try:
        await call
    except UaStatusCodeError as exc:
        return next(name for name in dir(ua.StatusCodes)
                    if getattr(ua.StatusCodes, name) == exc.code)
    return "Good"


def at(stamp: Any, seconds: float | None) -> bool:
    """An OPC UA timestamp is the given time.time() (to the microsecond it carries)."""
    return stamp is not None and seconds is not None and abs(stamp.timestamp() - seconds) < 1e-5


async def test_offline_values_are_bad_since_their_last_good_time_and_links_are_events() -> None:
    machine = three_links()
    a0, a2 = machine.axes["a0"], machine.axes["a2"]
    gateway = await start(machine)
    rounds = count_rounds(gateway, "a0")
    events: list[Any] = []

    class Handler:
        def event_notification(self, event: Any) -> None:
            events.append(event)

    try:
        async with Client(gateway.opcua.endpoint) as anon, \
                user_client(gateway.opcua.endpoint) as user:
            n = await names(anon)
            axes = await axes_of(anon, "bench")
            etype = await anon.nodes.base_event_type.get_child([f"{n.servobus}:LinkEventType"])
            subscription = await anon.create_subscription(20, Handler())
            await subscription.subscribe_events(await machine_node(anon, "bench"), etype)
            node = {(a, v): await parameter(anon, axes[a], v) for a in axes
                    for v in ("ActualPosition", "Online", "LastError", "PowerLost",
                              "PowerLostReason", "Interrupted")}

            async def status(axis: str) -> int:
                return int((await dv(node[axis, "ActualPosition"])).StatusCode.value)

            async def value(axis: str, name: str) -> Any:
                return (await dv(node[axis, name])).Value.Value

            await wait_until_async(lambda: _is(status("a0"), ua.StatusCodes.Good), timeout=10,
                                   what="a0 read")
            # a link down since start: no last known value, no time, no event
            late = await dv(node["a2", "ActualPosition"])
            assert late.StatusCode.value == ua.StatusCodes.BadNoCommunication
            assert late.SourceTimestamp is None and late.Value.Value is None
            online = await dv(node["a2", "Online"])
            assert online.StatusCode.is_good() and online.Value.Value is False
            assert "cannot open fake://late" in await value("a2", "LastError")

            # a link goes down: Bad since the last good read, once, and one event
            a0.interrupted = "a commanded motion may not have finished"
            a0.drop()
            await wait_until_async(lambda: _is(status("a0"), ua.StatusCodes.BadCommunicationError),
                                   timeout=10, what="a0 Bad while its link is down")
            bad = await dv(node["a0", "ActualPosition"])
            assert bad.Value.Value is None and at(bad.SourceTimestamp, a0.last_good)
            assert await value("a0", "Online") is False
            assert "stream closed" in await value("a0", "LastError")
            assert await value("a0", "Interrupted") == a0.interrupted
            assert await status("a1") == ua.StatusCodes.Good  # another link reads on
            await wait_until_async(lambda: events, timeout=10, what="the link's down event")
            since = rounds()
            await wait_until_async(lambda: rounds() >= since + 10, timeout=10,
                                   what="ten more rounds with the link down")
            assert len(events) == 1  # one event, not one per round or retry
            down = events[0]
            assert (down.LinkUrl, down.AxisNames, down.Online) == ("fake://line", "a0", False)
            assert "stream closed" in down.Reason and down.Severity == 700
            a0_node = axes["a0"]
            ack = f"{n.servobus}:Acknowledge"
            assert await code_of(a0_node.call_method(ack)) == "BadUserAccessDenied"
            user_a0 = (await axes_of(user, "bench"))["a0"]
            assert await code_of(user_a0.call_method(ack)) == "BadCommunicationError"

            # back, while the machine checks the drive for a power loss: still down
            a0.checking = True
            a0.back()
            await wait_until_async(lambda: _is(status("a0"), ua.StatusCodes.Good), timeout=10,
                                   what="a0 Good again")
            assert await code_of(user_a0.call_method(ack)) == "BadCommunicationError"
            assert len(events) == 1
            a0.power_lost_reason = "the position moved while the link was down"
            a0.checking = False
            await wait_until_async(lambda: len(events) == 2, timeout=10, what="the back event")
            back = events[1]
            assert (back.LinkUrl, back.Online, back.PowerLost) == ("fake://line", True, "a0")
            assert "acknowledge" in back.Message.Text
            await wait_until_async(lambda: _is(value("a0", "PowerLost"), True), timeout=10,
                                   what="PowerLost shown")
            assert await value("a0", "PowerLostReason") == a0.power_lost_reason
            assert await value("a0", "LastError") == ""
            move = f"{n.servobus}:MoveRelative"
            assert await code_of(user_a0.call_method(move, 1.0)) == "BadInvalidState"
            assert await code_of(user_a0.call_method(ack)) == "Good"
            assert machine.log == ["a0 ack"]
            await wait_until_async(lambda: _is(value("a0", "PowerLost"), False), timeout=10,
                                   what="PowerLost cleared")
            assert await value("a0", "Interrupted") == ""
            assert await code_of(user_a0.call_method(move, 1.0)) == "Good"
            assert machine.log == ["a0 ack", "a0 move_to 6"]

            # a link that could not be opened at start opens: its first "back"
            a2.back()
            await wait_until_async(lambda: len(events) == 3, timeout=10, what="a2's link back")
            assert (events[2].LinkUrl, events[2].Online) == ("fake://late", True)
            await wait_until_async(lambda: _is(status("a2"), ua.StatusCodes.Good), timeout=10,
                                   what="a2 read")
    finally:
        await gateway.close()


async def _is(value: Any, expected: object) -> bool:
    return bool(await value == expected)


def test_a_link_reopened_between_two_rounds_is_still_down_and_back() -> None:
    """The watch sees the machine's new Axis objects when a fast reconnect fell between two
    sampling rounds; a link being checked for a power loss is not back yet."""
    axes = [FakeAxis("a", []), FakeAxis("b", [])]
    watch = LinkWatch()
    assert watch.observe("l", axes) == []  # the first state is no event
    assert watch.observe("l", axes) == []
    axes[0].axis = object()  # type: ignore[assignment]  # reopened: a new Axis
    down, back = watch.observe("l", axes)
    assert (down.online, down.reason, back.online) == (False, REOPENED, True)
    assert down.axes == ("a", "b")
    for axis in axes:
        axis.drop()
    (down,) = watch.observe("l", axes)
    assert not down.online and "stream closed" in down.reason
    for axis in axes:
        axis.checking = True
        axis.back()
    assert watch.observe("l", axes) == []  # online, but checked: not back yet
    axes[1].power_lost_reason = "position jump"
    for axis in axes:
        axis.checking = False
    (back,) = watch.observe("l", axes)
    assert back.online and back.power_lost == ("b",)


# ---------------------------------------------------------------- MQTT
async def test_mqtt_state_link_messages_and_ack(tmp_path: Path) -> None:
    """The MQTT side alone (its sampler, commander and broker session; no OPC UA server,
    which takes seconds to start)."""
    with mosquitto(tmp_path) as port:
        machine = FakeMachine(count=1)
        sampler = Sampler(machine, 50)  # type: ignore[arg-type]
        mqtt = MqttGateway(machine, sampler, Commander(machine),  # type: ignore[arg-type]
                           MqttOptions(f"mqtt://127.0.0.1:{port}", username="gateway",
                                       password=BROKER_USERS["gateway"], commands=True,
                                       rate_hz=20))
        tasks = [asyncio.create_task(sampler.run()), asyncio.create_task(mqtt.run())]
        try:
            await wait_until_async(mqtt.connected.is_set, timeout=20,
                                   what="the gateway on the broker")
            async with aiomqtt.Client("127.0.0.1", port, username="tester",
                                      password=BROKER_USERS["tester"],
                                      identifier=f"t-{uuid.uuid4().hex}") as client:
                await _mqtt_recovery(machine, machine.axes["a0"], client)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)


async def _mqtt_recovery(machine: FakeMachine, a0: FakeAxis, client: aiomqtt.Client) -> None:
    base = "servobus/bench"
    await client.subscribe(f"{base}/link", qos=1)
    await client.subscribe(f"{base}/a0/state")
    await client.subscribe(f"{base}/a0/reply", qos=1)
    links: list[dict[str, Any]] = []
    states: list[dict[str, Any]] = []
    replies: list[dict[str, Any]] = []

    async def until(what: Callable[[], object], timeout: float = 20.0) -> None:
        if what():
            return
        async with asyncio.timeout(timeout):
            async for message in client.messages:
                body = json.loads(message.payload if isinstance(message.payload, bytes) else b"")
                topic = message.topic.value
                (links if topic.endswith("/link") else
                 replies if topic.endswith("/reply") else states).append(body)
                if what():
                    return

    async def command(**body: Any) -> dict[str, Any]:
        count = len(replies)
        await client.publish(f"{base}/a0/cmd", json.dumps(body), qos=1)
        await until(lambda: len(replies) > count)
        return replies[-1]

    await until(lambda: states and states[-1]["online"] and states[-1]["last_good"])
    good = states[-1]
    assert (good["ok"], good["power_lost"], good["power_lost_reason"],
            good["interrupted"]) == (True, False, None, None)
    a0.interrupted = "a commanded motion may not have finished"
    a0.drop()
    await until(lambda: links and states[-1]["online"] is False)
    assert links == [{"url": "fake://line", "axes": ["a0"], "online": False,
                      "reason": "the link fake://line is down: stream closed",
                      "last_good": round(a0.last_good or 0, 3), "power_lost": [],
                      "interrupted": ["a0"], "time": links[0]["time"]}]
    offline = states[-1]
    assert offline["ok"] is False and offline["position"] is None
    assert offline["last_good"] == round(a0.last_good or 0, 3)
    assert offline["interrupted"] == a0.interrupted
    a0.back(power_lost="the position moved while the link was down")
    await until(lambda: len(links) == 2 and states[-1]["power_lost"])
    assert (links[1]["online"], links[1]["power_lost"], links[1]["reason"]) == (
        True, ["a0"], None)
    assert states[-1]["power_lost_reason"] == "the position moved while the link was down"
    assert states[-1]["online"] is True and states[-1]["ok"] is True
    # ack allows motion again: an id and a fresh ts, as a motion command
    refused = await command(cmd="ack")
    assert (refused["ok"], refused["code"]) == (False, "BadInvalidArgument")
    moved = await command(id=uuid.uuid4().hex, ts=time.time(), cmd="move_relative", value=1.0)
    assert moved["code"] == "BadInvalidState"
    ident = uuid.uuid4().hex
    assert await command(id=ident, ts=time.time(), cmd="ack") == {
        "id": ident, "ok": True, "code": "Good"}
    assert machine.log == ["a0 ack"]
    await until(lambda: states[-1]["power_lost"] is False and states[-1]["interrupted"] is None)
    assert len(links) == 2


def test_the_documented_messages_have_the_fields_the_gateway_sends() -> None:
    """docs/gateway.md's state and link messages name exactly the fields sent."""
    text = (Path(servobus.__file__).parent.parent / "docs" / "gateway.md").read_text()
    blocks = [json.loads(b.split("```", 1)[0]) for b in text.split("```json\n")[1:]]
    documented = [set(b) for b in blocks if "position" in b or "axes" in b]
    sample = Sample("x", 1.0, True, health=Health(last_good=0.5))
    event = LinkEvent("u", ("x",), False, 1.0, "why")
    assert documented == [set(json.loads(state_json(sample, "mm"))),
                          set(json.loads(link_json(event)))]
