"""One identity per gateway on the broker (issue 30), the gateway's MQTT part in this process
through a real Mosquitto: one client id, a birth sequence, a live rival refused, a crashed
gateway's leftovers taken over, a half-open blip that ends ``online``, and hostile command
payloads each answered while the gateway goes on serving."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import struct
import uuid
from collections.abc import AsyncIterator, Iterator
from typing import Any

import aiomqtt
import pytest
from fake_machine import FakeMachine
from gateway_rig import BROKER_USERS, mosquitto
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.reasoncodes import ReasonCode
from rig import wait_until_async

from benchmarks.faults_hostile import hostile_mqtt, hostile_payloads, nested_4k
from servobus.errors import GatewayConflict
from servobus.gateway import mqtt as mqtt_module
from servobus.gateway import mqtt_presence
from servobus.gateway.commands import Commander
from servobus.gateway.mqtt import MqttGateway, MqttOptions, check_topics_free
from servobus.gateway.mqtt_presence import parse_seq
from servobus.gateway.sampler import Sampler

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def broker(tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    with mosquitto(tmp_path_factory.mktemp("mosquitto")) as port:
        yield port


def options(port: int, **more: Any) -> MqttOptions:
    return MqttOptions(f"mqtt://127.0.0.1:{port}", username="gateway",
                       password=BROKER_USERS["gateway"], **more)


class Running:
    """An MqttGateway (and its sampler) on a fake machine, run as tasks of this loop."""

    def __init__(self, port: int, name: str, **more: Any) -> None:
        self.machine = FakeMachine(name=name)
        self.sampler = Sampler(self.machine, 20)  # type: ignore[arg-type]
        self.mqtt = MqttGateway(self.machine, self.sampler,  # type: ignore[arg-type]
                                Commander(self.machine), options(port, **more))  # type: ignore[arg-type]
        self.tasks: list[asyncio.Task[None]] = []

    def start(self) -> Running:
        self.tasks = [asyncio.create_task(self.mqtt.run()),
                      asyncio.create_task(self.sampler.run())]
        return self

    async def born(self, births: int = 1) -> None:
        await wait_until_async(lambda: self.mqtt.presence.births >= births
                                and self.mqtt.connected.is_set(), timeout=30,
                                what=f"birth {births} of {self.mqtt.base}")

    async def stop(self) -> None:
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)


@contextlib.asynccontextmanager
async def running(port: int, name: str, **more: Any) -> AsyncIterator[Running]:
    gateway = Running(port, name, **more).start()
    try:
        yield gateway
    finally:
        await gateway.stop()


def observer(port: int) -> aiomqtt.Client:
    return aiomqtt.Client("127.0.0.1", port, username="tester",
                          password=BROKER_USERS["tester"], identifier=f"t-{uuid.uuid4().hex}")


async def retained(port: int, base: str) -> tuple[bytes | None, dict[str, Any] | None]:
    """The retained ``status`` and ``status/seq`` of ``base``."""
    got: dict[str, bytes] = {}
    async with observer(port) as client:
        for topic in (f"{base}/status", f"{base}/status/seq"):
            await client.subscribe(topic, qos=1)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(5):
                async for message in client.messages:
                    if message.retain and isinstance(message.payload, bytes):
                        got[message.topic.value] = message.payload
                    if len(got) == 2:
                        break
    seq = got.get(f"{base}/status/seq")
    return got.get(f"{base}/status"), None if seq is None else json.loads(seq)


# ---------------------------------------------------------------- a proxy that blips
class Pair:
    def __init__(self, gateway_side: asyncio.StreamWriter,
                 broker_side: asyncio.StreamWriter) -> None:
        self.gateway_side = gateway_side
        self.broker_side = broker_side  # held: a writer collected closes its socket
        self.silent = False  # the broker's side is left open and silent (half-open)
        self.broker_closed = asyncio.Event()


class BlipProxy:
    """Between the gateway and the broker. ``blip()`` resets the gateway's side of the
    newest connection and leaves the broker's side open with nothing more sent on it: the
    broker holds the old connection (and its will) until its keepalive runs out, unless a
    new connection takes its client id."""

    def __init__(self, upstream: int) -> None:
        self.upstream = upstream
        self.pairs: list[Pair] = []
        self.port = 0
        self._tasks: set[asyncio.Task[None]] = set()

    async def __aenter__(self) -> BlipProxy:
        self.server = await asyncio.start_server(self._accept, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.server.close()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    async def _accept(self, down_r: asyncio.StreamReader, down_w: asyncio.StreamWriter) -> None:
        up_r, up_w = await asyncio.open_connection("127.0.0.1", self.upstream)
        pair = Pair(down_w, up_w)
        self.pairs.append(pair)
        for coro in (self._to_broker(down_r, up_w, pair), self._to_gateway(up_r, down_w, pair)):
            task = asyncio.create_task(coro)
            self._tasks.add(task)

    @staticmethod
    async def _to_broker(reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                         pair: Pair) -> None:
        with contextlib.suppress(ConnectionError):
            while data := await reader.read(65536):
                if pair.silent:
                    break
                writer.write(data)
                await writer.drain()
        if not pair.silent:
            writer.close()

    @staticmethod
    async def _to_gateway(reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                          pair: Pair) -> None:
        with contextlib.suppress(ConnectionError):
            while data := await reader.read(65536):
                if not pair.silent:
                    writer.write(data)
        pair.broker_closed.set()
        if not pair.silent:
            writer.close()

    def blip(self) -> Pair:
        pair = self.pairs[-1]
        pair.silent = True
        sock = pair.gateway_side.get_extra_info("socket")
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        pair.gateway_side.transport.abort()  # RST: the gateway learns at once
        return pair


# ---------------------------------------------------------------- tests
async def test_a_half_open_blip_ends_online(broker: int,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 30: after a half-open blip the gateway came back online at once, and its old
    connection's will set ``offline`` 15 s later. With one client id the reconnect takes
    the old connection over: the broker lets it go then, and the status ends online."""
    monkeypatch.setattr(mqtt_module, "RECONNECT_S", 0.1)
    async with BlipProxy(broker) as proxy, running(proxy.port, "blip-cell") as gateway:
        await gateway.born()
        assert gateway.mqtt.presence.client_id == "servobus-blip-cell"
        old = proxy.blip()
        await gateway.born(2)
        await asyncio.wait_for(old.broker_closed.wait(), 30)  # taken over, not timed out
        status, seq = await retained(broker, "servobus/blip-cell")
        assert status == b"online"
        assert seq is not None and seq["seq"] == gateway.mqtt.presence.seq == 1
        assert seq["gateway"] == "blip-cell"


async def test_a_second_gateway_on_the_same_topics_is_refused(
        broker: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # a loaded machine may delay the first's heartbeat: the probe waits longer (it returns
    # at the first heartbeat, so this costs nothing)
    monkeypatch.setattr(mqtt_presence, "LIVENESS_S", 10.0)
    async with running(broker, "twin-cell") as first:
        await first.born()
        second = Running(broker, "twin-cell", gateway_id="other-pc")
        with pytest.raises(GatewayConflict, match="served by a live gateway"):
            await second.mqtt.run()  # it never served these topics: it refuses
        with pytest.raises(GatewayConflict, match="gateway id twin-cell, birth 0"):
            await check_topics_free(options(broker), "twin-cell")  # the check before opening
        # the first was never disconnected: same birth, and its heartbeat goes on live
        beats: list[dict[str, Any]] = []
        async with observer(broker) as client:
            await client.subscribe("servobus/twin-cell/status/seq")
            async with asyncio.timeout(10):
                async for message in client.messages:
                    if not message.retain and isinstance(message.payload, bytes):
                        beats.append(json.loads(message.payload))
                        break
        assert beats[0]["seq"] == 0 and first.mqtt.presence.births == 1
        assert first.mqtt.connected.is_set()
        # another machine name, or another prefix, is another set of topics
        await check_topics_free(options(broker), "twin-cell-2")
        await check_topics_free(options(broker, prefix="plant/line-2"), "twin-cell")


async def test_a_crashed_gateway_is_taken_over_by_its_restart(
        broker: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Its own retained ``online`` is no rival: without a heartbeat it is a leftover,
    whether the broker has let the old connection go (the will fired: ``offline``) or
    still holds it half-open."""
    monkeypatch.setattr(mqtt_presence, "LIVENESS_S", 1.5)
    async with BlipProxy(broker) as proxy:
        crashed = Running(proxy.port, "crash-cell").start()
        await crashed.born()
        old = proxy.blip()  # the network is gone, then the process
        await crashed.stop()
        assert (await retained(broker, "servobus/crash-cell"))[0] == b"online"  # a leftover
        async with running(broker, "crash-cell") as restarted:
            await restarted.born()
            assert restarted.mqtt.presence.seq == 1  # after the crashed one's 0
            await asyncio.wait_for(old.broker_closed.wait(), 30)
            status, seq = await retained(broker, "servobus/crash-cell")
            assert status == b"online" and seq is not None and seq["seq"] == 1
        # a clean stop says offline; the next start is not delayed by a probe's wait
        assert (await retained(broker, "servobus/crash-cell"))[0] == b"offline"
        async with running(broker, "crash-cell") as again:
            await again.born()
            assert again.mqtt.presence.seq == 2


def test_a_seq_message_is_read_only_when_it_is_one() -> None:
    """Anyone the broker lets publish on ``status/seq`` may write anything there."""
    assert parse_seq(b'{"seq":3,"gateway":"g","since":1.5,"time":2}') == (3, "g", 1.5)
    assert parse_seq(b'{"seq":3,"gateway":7,"since":"x"}') == (3, "", None)
    for junk in (b"", b"[]", b"null", b'{"seq":-1}', b'{"seq":true}', b'{"seq":"3"}',
                 b'{"seq":1e400}', b"{" * 600, b"\xff", nested_4k()):
        assert parse_seq(junk) is None, junk


class RefusingBroker:
    """An aiomqtt client whose broker refuses every subscription (its ACL)."""

    def __init__(self, refusal: object) -> None:
        self.refusal = refusal
        self.messages: list[object] = []

    async def __aenter__(self) -> RefusingBroker:
        return self

    async def __aexit__(self, *exc: object) -> None:
        return None

    async def subscribe(self, topic: object, qos: int = 0) -> list[object]:
        return [self.refusal] * (len(topic) if isinstance(topic, list) else 1)


@pytest.mark.parametrize("refusal", [128, ReasonCode(PacketTypes.SUBACK, identifier=0x87)],
                         ids=["MQTT 3.1.1", "MQTT 5"])
async def test_a_broker_that_refuses_the_probe_leaves_the_check_undone(
        refusal: object, caplog: pytest.LogCaptureFixture) -> None:
    """The gateway must not stop serving for want of a safety net: it connects, and says
    once that it could not look for a rival."""
    gateway = Running(1883, "acl-cell")
    broker = RefusingBroker(refusal)
    gateway.mqtt.client = lambda probe=False: broker  # type: ignore[method-assign]
    with caplog.at_level("WARNING", logger="servobus.gateway.mqtt"):
        assert await gateway.mqtt.claim() and await gateway.mqtt.claim()
    told = [r for r in caplog.records if "refused this gateway's subscription" in r.message]
    assert len(told) == 1


def test_the_hostile_payloads_hold_the_three_of_the_issue() -> None:
    payloads = hostile_payloads(300, seed=30)
    assert len(payloads) == 300 and payloads == hostile_payloads(300, seed=30)
    assert payloads[0].count(b"0") >= 399 and b'"value":1000' in payloads[0]
    assert b'"ts":1000' in payloads[1]
    assert payloads[2] == nested_4k() and len(payloads[2]) == 4096
    assert payloads[2].count(b"[") == 1000


async def test_hostile_commands_are_each_answered_and_the_gateway_serves_on(
        broker: int) -> None:
    async with running(broker, "fuzz-cell", commands=True) as gateway:
        await gateway.born()
        result = await hostile_mqtt("127.0.0.1", broker, "tester", BROKER_USERS["tester"],
                                    "servobus/fuzz-cell", "a0", count=300, timeout=60)
        assert result["sent"] == 300
        assert result["answered"] == 300, result
        assert result["serving"], result
        assert not any(task.done() for task in gateway.tasks)
        assert "BadInternalError" not in result["codes"], result["codes"]
        # nothing moved: the fake axes saw stops at most
        assert all(entry.endswith(" stop") for entry in gateway.machine.log), \
            gateway.machine.log
