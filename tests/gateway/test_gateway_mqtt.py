"""``servobus serve --mqtt`` through a real Mosquitto broker, read with aiomqtt."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
from gateway_rig import BROKER_USERS, RunningGateway, mosquitto, start_gateway

TOPIC = "servobus/virtual-cell"
GATEWAY_ENV = {"SERVOBUS_MQTT_PASSWORD": BROKER_USERS["gateway"]}


@pytest.fixture(scope="module")
def broker(tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    with mosquitto(tmp_path_factory.mktemp("mosquitto")) as port:
        yield port


@pytest.fixture(scope="module")
def gateway(broker: int) -> Iterator[RunningGateway]:
    running = start_gateway("--mqtt", f"mqtt://127.0.0.1:{broker}", "--mqtt-user", "gateway",
                            "--mqtt-commands", "--mqtt-rate", "20", "--rate", "50",
                            env=GATEWAY_ENV)
    yield running
    running.stop()


def mqtt_client(port: int) -> aiomqtt.Client:
    return aiomqtt.Client("127.0.0.1", port, username="tester",
                          password=BROKER_USERS["tester"], identifier=f"t-{uuid.uuid4().hex}")


async def collect(client: aiomqtt.Client, done: Any, timeout: float = 20.0) -> None:
    """Feed messages to ``done(topic, payload, retain)`` until it returns True."""
    async with asyncio.timeout(timeout):
        async for message in client.messages:
            payload = message.payload if isinstance(message.payload, bytes) else b""
            if done(message.topic.value, payload, bool(message.retain)):
                return


async def test_state_messages_reach_a_subscriber(broker: int, gateway: RunningGateway) -> None:
    states: dict[str, dict[str, Any]] = {}
    async with mqtt_client(broker) as client:
        await client.subscribe(f"{TOPIC}/+/state")
        await collect(client, lambda topic, payload, _: states.update(
            {topic.split("/")[2]: json.loads(payload)}) or len(states) == 3)
    assert sorted(states) == ["c", "x", "y"]
    for axis, unit in (("x", "mm"), ("y", "mm"), ("c", "deg")):
        body = states[axis]
        assert {"position", "speed", "moving", "alarm", "unit"} <= set(body)
        assert body["unit"] == unit and body["ok"] is True and body["alarm"] == 0
        assert isinstance(body["position"], float)


async def test_status_and_alarms_are_retained(broker: int, gateway: RunningGateway) -> None:
    async def four(retained_only: bool) -> dict[str, bytes]:
        got: dict[str, bytes] = {}
        async with mqtt_client(broker) as client:
            await client.subscribe(f"{TOPIC}/status")
            await client.subscribe(f"{TOPIC}/+/alarm")

            def seen(topic: str, payload: bytes, retain: bool) -> bool:
                if retain or not retained_only:
                    got[topic] = payload
                return len(got) == 4
            await collect(client, seen)
        return got

    await four(retained_only=False)  # published (live, or already retained)
    retained = await four(retained_only=True)  # a later subscriber gets them from the broker
    assert retained[f"{TOPIC}/status"] == b"online"
    for axis in "xyc":
        assert json.loads(retained[f"{TOPIC}/{axis}/alarm"])["code"] == 0


async def test_a_command_runs_once_and_the_refusals_say_why(broker: int,
                                                            gateway: RunningGateway) -> None:
    replies: list[dict[str, Any]] = []
    positions: list[float] = []
    async with mqtt_client(broker) as client:
        await client.subscribe(f"{TOPIC}/x/reply", qos=1)
        await client.subscribe(f"{TOPIC}/x/state")

        def note(topic: str, payload: bytes, _: bool) -> bool:
            if topic.endswith("/reply"):
                replies.append(json.loads(payload))
            elif payload:
                positions.append(json.loads(payload)["position"])
            return False

        async def until(what: Any) -> None:
            def check(topic: str, payload: bytes, retain: bool) -> bool:
                note(topic, payload, retain)
                return bool(what())
            await collect(client, check)

        await until(lambda: positions)
        start = positions[-1]
        move = {"id": uuid.uuid4().hex, "ts": time.time(), "cmd": "move_relative", "value": 1.5}
        await client.publish(f"{TOPIC}/x/cmd", json.dumps(move), qos=1)
        await until(lambda: replies)
        assert replies[-1] == {"id": move["id"], "ok": True, "code": "Good"}
        await until(lambda: abs(positions[-1] - (start + 1.5)) < 0.01)
        # the same message again (a QoS 1 redelivery), as retained, and stale: never run
        await client.publish(f"{TOPIC}/x/cmd", json.dumps(move), qos=1)
        retained = {**move, "id": uuid.uuid4().hex, "ts": time.time()}
        await client.publish(f"{TOPIC}/x/cmd", json.dumps(retained), qos=1, retain=True)
        await client.publish(f"{TOPIC}/x/cmd", b"", qos=1, retain=True)  # clear it again
        stale = {**move, "id": uuid.uuid4().hex, "ts": time.time() - 60}
        await client.publish(f"{TOPIC}/x/cmd", json.dumps(stale), qos=1)
        await until(lambda: len(replies) >= 5)
        by_id = {r["id"]: r for r in replies[1:]}
        assert by_id[move["id"]]["code"] == "BadRequestNotAllowed"
        assert by_id[retained["id"]]["code"] == "BadRequestNotAllowed"
        assert by_id[stale["id"]]["code"] == "BadInvalidTimestamp"
        assert not any(r["ok"] for r in replies[1:])
        count = len(positions)
        await until(lambda: len(positions) >= count + 5)  # a few more state messages
        assert abs(positions[-1] - (start + 1.5)) < 0.01  # moved once, not again


async def test_a_killed_gateway_leaves_its_last_will(broker: int, gateway: RunningGateway,
                                                     tmp_path: Path) -> None:
    """And only its own: the gateway of another machine on the broker stays online (each
    has a client id of its own, servobus-<gateway id>)."""
    machine = tmp_path / "will.toml"
    machine.write_text('name = "will-cell"\n[axes.z]\nurl = "sim://dyn232?fast=1"\nid = 1\n'
                       'unit = "mm"\nper_rev = 5.0\n')
    running = start_gateway("--machine", str(machine), "--mqtt", f"mqtt://127.0.0.1:{broker}",
                            "--mqtt-user", "gateway", env=GATEWAY_ENV)
    statuses: list[bytes] = []
    try:
        async with mqtt_client(broker) as client:
            await client.subscribe("servobus/will-cell/status", qos=1)
            await collect(client, lambda _t, payload, _r: statuses.append(payload)
                          or payload == b"online")
            running.proc.send_signal(signal.SIGKILL)  # no clean stop: the broker tells
            await collect(client, lambda _t, payload, _r: statuses.append(payload)
                          or payload == b"offline")
    finally:
        running.stop()
    assert statuses[-1] == b"offline"
    assert await retained_status(broker, TOPIC) == b"online"


async def retained_status(port: int, base: str) -> bytes:
    async with mqtt_client(port) as client:
        await client.subscribe(f"{base}/status", qos=1)
        got: list[bytes] = []

        def first_retained(_topic: str, payload: bytes, retain: bool) -> bool:
            if retain:
                got.append(payload)
            return bool(got)
        await collect(client, first_retained)
    return got[0]


@pytest.mark.slow
def test_a_second_gateway_of_the_same_machine_refuses_to_start(
        broker: int, gateway: RunningGateway) -> None:
    """Issue 30: it would take the first one's client id (the broker would drop the first)
    and interleave its state on the same topics. It refuses before it opens the machine,
    and the first one serves on."""
    cmd = [sys.executable, "-m", "servobus", "serve", "--opcua", "opc.tcp://127.0.0.1:0",
           "--mqtt", f"mqtt://127.0.0.1:{broker}", "--mqtt-user", "gateway"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60,
                          env={**os.environ, **GATEWAY_ENV})
    assert done.returncode == 2, done.stderr
    assert "error: MQTT topics servobus/virtual-cell/... on broker 127.0.0.1:" in done.stderr
    assert "served by a live gateway (gateway id virtual-cell, birth 0" in done.stderr
    assert "ready" not in done.stdout
    assert gateway.proc.poll() is None
    assert asyncio.run(retained_status(broker, TOPIC)) == b"online"


async def test_set_speed_ends_by_itself_when_its_sender_stops_sending(
        broker: int, gateway: RunningGateway) -> None:
    """Issue 27: set_speed is a lease of its sender, renewed by sending it again with a new
    id; when the sender goes silent the axis comes to rest within the ttl (plus the ramp
    down and the state's period; a loaded machine is given more)."""
    ttl, late_s, rest_s = 0.4, 2.0, 0.5
    replies: list[dict[str, Any]] = []
    states: list[tuple[float, dict[str, Any]]] = []  # (arrival, state)
    async with mqtt_client(broker) as client:
        await client.subscribe(f"{TOPIC}/y/reply", qos=1)
        await client.subscribe(f"{TOPIC}/y/state")

        async def until(what: Any) -> None:
            def check(topic: str, payload: bytes, _: bool) -> bool:
                if topic.endswith("/reply"):
                    replies.append(json.loads(payload))
                elif payload:
                    states.append((time.monotonic(), json.loads(payload)))
                return bool(what())
            await collect(client, check)

        async def set_speed() -> float:
            sent = time.monotonic()
            body = {"id": uuid.uuid4().hex, "ts": time.time(), "cmd": "set_speed",
                    "value": 10.0, "ttl": ttl, "client": "test-line"}
            count = len(replies)
            await client.publish(f"{TOPIC}/y/cmd", json.dumps(body), qos=1)
            await until(lambda: len(replies) > count)
            assert replies[-1] == {"id": body["id"], "ok": True, "code": "Good"}
            return sent

        def at_rest_since() -> float | None:
            """When the last run of standstill states began, if it spans rest_s (a late
            target update on a loaded machine may halt the motor for a moment)."""
            run = 0
            while run < len(states) and states[-1 - run][1]["speed"] == 0.0 \
                    and not states[-1 - run][1]["moving"]:
                run += 1
            if not run or states[-1][0] - states[-run][0] < rest_s:
                return None
            return states[-run][0]

        await set_speed()
        await until(lambda: states and states[-1][1]["speed"] > 5.0)  # turning
        last = await set_speed()  # renewed: then silent
        await until(lambda: at_rest_since() is not None and at_rest_since() > last)
        stopped = at_rest_since()
        assert stopped is not None and stopped - last <= ttl + late_s
