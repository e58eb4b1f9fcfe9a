"""The gateway's constant speed is a lease (issue 27), in this process on a machine of
in-process virtual drives: OPC UA ``SetSpeed(Value, Ttl)`` and MQTT ``set_speed`` with
``ttl`` hold an axis only while their owner renews them; a closed session lets go; the
gateway's shutdown ends every lease before it stops the axes."""

from __future__ import annotations

import json
import time
import uuid
import weakref
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
from asyncua import Client, ua
from asyncua.ua.uaerrors import UaStatusCodeError
from gateway_rig import BROKER_USERS, PASSWORD, USER, axes_of, mosquitto, names
from rig import wait_until_async

from servobus.gateway.mqtt import MqttOptions
from servobus.gateway.opcua_server import OpcUaOptions
from servobus.gateway.serve import Gateway, GatewayOptions
from servobus.gateway.users import Users
from servobus.machine import AsyncMachine, open_machine_async
from servobus.machine.lease import Lease

CELL = """name = "lease-cell"
[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-1000.0, 1000.0]
[axes.spindle]
url = "sim://dyn232?fast=1"
id = 2
unit = "rev"
per_rev = 1.0
continuous = true
"""
#: A lease's end is checked by the streamer every 50 ms; on a loaded machine a loop turn
#: may be late by a few hundred ms: the end must come within the ttl plus this.
LATE_S = 1.0


@pytest.fixture
async def machine(tmp_path: Path) -> AsyncIterator[AsyncMachine]:
    path = tmp_path / "cell.toml"
    path.write_text(CELL)
    m = await open_machine_async(path)
    try:
        yield m
    finally:
        await m.close()


async def start(machine: AsyncMachine, mqtt: MqttOptions | None = None) -> Gateway:
    users = Users()
    users.add(USER, PASSWORD)
    gateway = Gateway(machine, GatewayOptions(OpcUaOptions("opc.tcp://127.0.0.1:0",
                                                           users=users),
                                              mqtt=mqtt, rate_hz=20))
    await gateway.start()
    return gateway


def user_client(endpoint: str) -> Client:
    client = Client(endpoint)
    client.set_user(USER)
    client.set_password(PASSWORD)
    return client


async def set_speed(client: Client, axis: str, *args: object) -> None:
    """Call the axis's SetSpeed; its node browsed once per client (a renewal must not
    wait for a browse on a loaded machine)."""
    known = _nodes.setdefault(client, {})
    if axis not in known:
        n = await names(client)
        known[axis] = ((await axes_of(client, "lease-cell"))[axis], f"{n.servobus}:SetSpeed")
    node, method = known[axis]
    await node.call_method(method, *args)


_nodes: weakref.WeakKeyDictionary[Client, dict[str, tuple[Any, str]]] = \
    weakref.WeakKeyDictionary()


async def refusal(client: Client, axis: str, *args: object) -> str:
    """The name of the status code the call is refused with."""
    with pytest.raises(UaStatusCodeError) as refused:
        await set_speed(client, axis, *args)
    return next(name for name in dir(ua.StatusCodes)
                if getattr(ua.StatusCodes, name) == refused.value.code)


def live(machine: AsyncMachine, axis: str = "x") -> Lease:
    lease = machine.axes[axis].lease
    assert lease is not None, f"axis {axis} holds no lease"
    return lease


async def renew_until(calls: int, ttl: float, renew: Any, lease: Lease) -> float:
    """Renew ``calls`` times, each when a quarter of the ttl is gone (the rest is slack for
    a loaded machine); when the last call was sent (the lease runs at least ttl from then).
    """
    last = time.monotonic()
    for _ in range(calls):
        await wait_until_async(lambda: lease.until - time.monotonic() < ttl * 0.75,
                               timeout=5, what="a quarter of the ttl gone")
        assert lease.alive, f"the lease ended while renewed: {lease.ended}"
        last = time.monotonic()
        await renew()
    return last


async def test_set_speed_holds_while_renewed_ends_within_its_ttl_and_at_shutdown(
        machine: AsyncMachine) -> None:
    """One gateway (an asyncua server takes 2 s to start) for both: a renewed SetSpeed
    runs past its first ttl and ends by itself ttl after the last call; the gateway's
    shutdown ends every lease before it stops the axes (a continuous one too)."""
    gateway = await start(machine)
    try:
        async with user_client(gateway.opcua.endpoint) as client:
            ttl = 0.8
            first = time.monotonic()
            await set_speed(client, "x", 20.0, ttl)
            lease = live(machine)
            assert lease.owner.startswith("opcua session ") and f"({USER})" in lease.owner
            last = await renew_until(5, ttl, lambda: set_speed(client, "x", 20.0, ttl), lease)
            assert last - first > ttl  # alive past its first ttl: renewed, the same lease
            assert machine.axes["x"].lease is lease
            await wait_until_async(lambda: not lease.alive, timeout=ttl + LATE_S,
                                   what="the lease ending by itself")
            assert lease.ended == "expired"
            assert time.monotonic() - last >= ttl
            x = machine.axes["x"].core()
            await wait_until_async(lambda: _zero(x.speed()), timeout=5, what="standstill")

            await set_speed(client, "x", 20.0, 1.0)
            await set_speed(client, "spindle", 2.0, 1.0)
            lease = live(machine)
            spindle = machine.axes["spindle"].core()
            await wait_until_async(lambda: _nonzero(spindle.speed()), timeout=5,
                                   what="the spindle turning")
            await gateway.close()
            assert not lease.alive and lease.ended == "stopped"  # ended first, not expired
        await wait_until_async(lambda: _zero(x.speed()), timeout=5, what="x at standstill")
        await wait_until_async(lambda: _zero(spindle.speed()), timeout=5,
                               what="the spindle at standstill")
    finally:
        await gateway.close()


async def test_arguments_owners_and_a_closed_session(machine: AsyncMachine) -> None:
    gateway = await start(machine)
    try:
        async with user_client(gateway.opcua.endpoint) as a, \
                user_client(gateway.opcua.endpoint) as b:
            # Ttl is required, a finite number above 0 and at most 1 s; nothing moves
            assert await refusal(a, "x", 20.0) == "BadArgumentsMissing"
            assert await refusal(a, "x", 20.0, 1.5) == "BadOutOfRange"
            assert await refusal(a, "x", 20.0, 0.0) == "BadOutOfRange"
            assert await refusal(a, "x", 20.0, float("nan")) == "BadInvalidArgument"
            assert machine.axes["x"].lease is None
            await set_speed(a, "x", 20.0, 1.0)
            lease = live(machine)
            # another session is refused while the lease lives; Stop always wins
            assert await refusal(b, "x", -20.0, 1.0) == "BadLocked"
            assert live(machine) is lease and lease.speed == 20.0
            n = await names(b)
            await (await axes_of(b, "lease-cell"))["x"].call_method(f"{n.servobus}:Stop")
            assert not lease.alive and lease.ended == "stopped"
            await set_speed(b, "x", -20.0, 1.0)  # now b holds it
            held = live(machine)
            assert held.owner != lease.owner
            # a continuous axis turns open-ended: no lease, the Ttl only checked
            await set_speed(a, "spindle", 1.0, 0.5)
            assert machine.axes["spindle"].lease is None
        # both sessions closed (CloseSession): b's lease ended at once, not by its ttl
        assert not held.alive and held.ended == "stopped"
        spindle = machine.axes["spindle"].core()
        assert abs(await spindle.speed()) > 0  # still turning: open-ended, as documented
    finally:
        await gateway.close()


async def _zero(speed: Any) -> bool:
    return bool(await speed == 0)


async def _nonzero(speed: Any) -> bool:
    return bool(await speed != 0)


# ---------------------------------------------------------------- MQTT
async def test_mqtt_set_speed_ends_by_itself_when_its_sender_stops_sending(
        machine: AsyncMachine, tmp_path: Path) -> None:
    with mosquitto(tmp_path) as port:
        gateway = await start(machine, MqttOptions(
            f"mqtt://127.0.0.1:{port}", username="gateway", password=BROKER_USERS["gateway"],
            commands=True))
        try:
            await wait_until_async(gateway.mqtt.connected.is_set,  # type: ignore[union-attr]
                                   timeout=20, what="the gateway on the broker")
            async with aiomqtt.Client("127.0.0.1", port, username="tester",
                                      password=BROKER_USERS["tester"]) as client:
                await _mqtt_lease(machine, client)
        finally:
            await gateway.close()


async def _mqtt_lease(machine: AsyncMachine, client: aiomqtt.Client) -> None:
    topic = "servobus/lease-cell/x"
    await client.subscribe(f"{topic}/reply", qos=1)
    replies: dict[str, dict[str, Any]] = {}

    async def send(**body: Any) -> dict[str, Any]:
        ident = uuid.uuid4().hex
        await client.publish(f"{topic}/cmd", json.dumps({"id": ident, "ts": time.time(),
                                                         **body}), qos=1)
        async for message in client.messages:
            reply = json.loads(message.payload if isinstance(message.payload, bytes) else b"")
            replies[reply["id"]] = reply
            if ident in replies:
                return replies[ident]
        raise AssertionError("no reply")

    for bad, code in ((2.0, "BadOutOfRange"), (0, "BadOutOfRange"), ("1", "BadInvalidArgument")):
        reply = await send(cmd="set_speed", value=10.0, ttl=bad)
        assert (reply["ok"], reply["code"]) == (False, code), (bad, reply)
    assert machine.axes["x"].lease is None
    reply = await send(cmd="set_speed", value=10.0, ttl=0.8, client="line-3")
    assert reply["ok"], reply
    lease = live(machine)
    assert lease.owner == "mqtt:line-3"
    other = await send(cmd="set_speed", value=-10.0)  # no client: owner "mqtt", refused
    assert other["code"] == "BadLocked" and "mqtt:line-3" in other["error"]

    async def renew() -> None:
        assert (await send(cmd="set_speed", value=10.0, ttl=0.8, client="line-3"))["ok"]

    last = await renew_until(3, 0.8, renew, lease)
    await wait_until_async(lambda: not lease.alive, timeout=0.8 + LATE_S,
                           what="the MQTT lease ending by itself")
    assert lease.ended == "expired" and time.monotonic() - last >= 0.8
