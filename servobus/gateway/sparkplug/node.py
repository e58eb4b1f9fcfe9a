"""``servobus serve --sparkplug GROUP``: the gateway as a Sparkplug B edge node.

Decisions (docs/gateway.md "Sparkplug B"):

* Its own MQTT connection (client id ``servobus-<gateway id>-spb``), beside the JSON
  topics' one: a connection has one will, and the NDEATH must be this one's.
* Topics ``spBv1.0/<group>/<type>/<gateway id>[/<axis>]``: the edge node is the gateway,
  each axis a device.
* bdSeq: 0 at the first connection of the process, one more (mod 256) at each new
  connection; the will (NDEATH, QoS 1, not retained) carries the bdSeq of the NBIRTH that
  follows on that connection. seq: 0 in the NBIRTH, then one more (mod 256) for each DBIRTH,
  DDATA in publishing order. On a clean stop the NDEATH is published before disconnecting.
* NCMD ``Node Control/Rebirth`` true: the NBIRTH (same bdSeq, seq 0) and every DBIRTH again.
* DDATA by exception every ``1 / --mqtt-rate`` seconds: only the metrics that changed.
* DCMD only with ``--mqtt-commands`` (the gateway logs in to the broker, whose ACL says who
  may publish to ``.../DCMD/...``): servobus.gateway.sparkplug.commands decides, the result
  comes back as ``Commands/Result`` and ``Commands/Error`` in a DDATA.
* Not done: aliases, DDEATH (an offline axis keeps its device, ``Online`` false, readings
  null), a primary host's STATE (the node publishes whether or not a host is online).
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import aiomqtt
from paho.mqtt.subscribeoptions import SubscribeOptions

from servobus.errors import InvalidValue
from servobus.gateway.commands import Commander, Refused
from servobus.gateway.identity import client_id, gateway_id
from servobus.gateway.mqtt import (
    MqttGateway,
    MqttOptions,
    broker_client,
    broker_user,
    check_topic_name,
    keep_connected,
    paho_of,
    parse_broker,
    run_session,
)
from servobus.gateway.sampler import Sampler
from servobus.gateway.source import Machine
from servobus.gateway.sparkplug.commands import OWNER, DcmdGate
from servobus.gateway.sparkplug.payload import (
    BOOLEAN,
    REBIRTH,
    RESULT,
    RESULT_ERROR,
    SEQ_MODULO,
    STRING,
    Metrics,
    command_metrics,
    device_metrics,
    metric_value,
    node_birth,
    node_death,
    payload,
    topic,
    units,
)
from servobus.gateway.sparkplug.schema import Payload

log = logging.getLogger(__name__)
BAD_GROUP = set("+#/\0")


def check_group(group: str) -> str:
    if not group or BAD_GROUP & set(group):
        raise InvalidValue(f"--sparkplug {group!r}: a Sparkplug group id is one topic level "
                           "(no '/', '+', '#')")
    return group


class SparkplugNode:
    def __init__(self, machine: Machine, sampler: Sampler, commander: Commander,
                 options: MqttOptions, group: str) -> None:
        for name in machine.axes:
            check_topic_name("axis", name)
        self.machine = machine
        self.sampler = sampler
        self.commander = commander
        self.options = options
        self.group = check_group(group)
        self.node = gateway_id(machine.name, options.gateway_id)
        self.client_id = f"{client_id(self.node)}-spb"
        self.broker = parse_broker(options.url)
        self.user = f"mqtt:{broker_user(options, self.broker, 'DCMD (--mqtt-commands)')}"
        self.gate = DcmdGate(options.max_age_s)
        self.bd_seq = -1  # the first connection takes 0
        self.seq = 0
        self.births = 0  # NBIRTHs published (rebirths included)
        self.connected = asyncio.Event()
        self._units = {name: units(axis) for name, axis in machine.axes.items()}
        self._sent: dict[str, Metrics] = {}
        self._paho: object = None

    def topic(self, kind: str, device: str | None = None) -> str:
        return topic(self.group, kind, self.node, device)

    async def run(self) -> None:
        """Serve until cancelled; a new connection (and bdSeq) after a lost broker."""
        await keep_connected(self._connect, self.connected, "Sparkplug: broker", self.broker,
                             log)

    async def _connect(self) -> None:
        self.bd_seq = (self.bd_seq + 1) % SEQ_MODULO
        will = aiomqtt.Will(self.topic("NDEATH"), node_death(self.bd_seq), qos=1, retain=False)
        async with broker_client(self.options, self.client_id, will) as client:
            await self._session(client)

    async def _session(self, client: aiomqtt.Client) -> None:
        self._paho = paho_of(client)
        await client.subscribe(self.topic("NCMD"), qos=1)  # before the birth (the spec)
        if self.options.commands:
            await client.subscribe(self.topic("DCMD", "+"), options=SubscribeOptions(
                qos=1, retainAsPublished=True))
        await self._births(client)
        log.info("Sparkplug: edge node %s/%s on %s:%s, bdSeq %d%s", self.group, self.node,
                 self.broker.host, self.broker.port, self.bd_seq,
                 " (DCMD on)" if self.options.commands else "")
        self.connected.set()
        tasks = [asyncio.create_task(self._data_loop(client)),
                 asyncio.create_task(self._message_loop(client))]
        await run_session(tasks, lambda: client.publish(self.topic("NDEATH"),
                                                         node_death(self.bd_seq), qos=1))

    async def _send(self, client: aiomqtt.Client, kind: str, device: str | None,
                    message: Any) -> None:
        """QoS 0, not retained, the next seq set just before the publish (in order)."""
        if kind == "NBIRTH":
            self.seq = 0
        else:
            self.seq = (self.seq + 1) % SEQ_MODULO
        message.seq = self.seq
        await MqttGateway._send_state(client, self._paho, self.topic(kind, device),
                                      message.SerializeToString())

    async def _births(self, client: aiomqtt.Client) -> None:
        await self._send(client, "NBIRTH", None, node_birth(self.bd_seq, self.machine.name))
        self.births += 1
        for name in self.machine.axes:
            before = self._sent.get(name, {})
            metrics = {**device_metrics(self.sampler.latest.get(name)),
                       **command_metrics(str(before.get(RESULT, (STRING, ""))[1]),
                                         str(before.get(RESULT_ERROR, (STRING, ""))[1]))}
            self._sent[name] = metrics
            await self._send(client, "DBIRTH", name, payload(metrics, None,
                                                             unit_of=self._units[name]))

    async def _data_loop(self, client: aiomqtt.Client) -> None:
        period = 1.0 / self.options.rate_hz
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            for name in self.machine.axes:
                await self._changes(client, name, device_metrics(self.sampler.latest.get(name)))
            next_at = max(next_at + period, loop.time())
            await asyncio.sleep(next_at - loop.time())

    async def _changes(self, client: aiomqtt.Client, name: str, metrics: Metrics) -> None:
        sent = self._sent.setdefault(name, {})
        changed = {key: value for key, value in metrics.items() if sent.get(key) != value}
        if changed:
            sent.update(changed)
            await self._send(client, "DDATA", name, payload(changed, None))

    async def _message_loop(self, client: aiomqtt.Client) -> None:
        """Each NCMD and DCMD in its own error boundary; a lost broker ends the session."""
        async for message in client.messages:
            data = message.payload if isinstance(message.payload, bytes) else b""
            parts = message.topic.value.split("/")
            try:
                if len(parts) == 4 and parts[2] == "NCMD":
                    await self._node_command(client, data)
                elif len(parts) == 5 and parts[2] == "DCMD":
                    await self._device_command(client, parts[4], data, bool(message.retain))
            except (aiomqtt.MqttError, asyncio.CancelledError):
                raise
            except Exception as exc:
                log.error("Sparkplug: %s failed unexpectedly: %s: %s", message.topic.value,
                          type(exc).__name__, exc)

    async def _node_command(self, client: aiomqtt.Client, data: bytes) -> None:
        try:
            metrics = Payload.FromString(data).metrics
        except Exception:  # not a payload: nothing asked
            log.warning("Sparkplug: an NCMD that is not a Sparkplug B payload was ignored")
            return
        if any(m.name == REBIRTH and m.datatype in (0, BOOLEAN) and metric_value(m) is True
               for m in metrics):
            log.info("Sparkplug: rebirth requested")
            await self._births(client)

    async def _device_command(self, client: aiomqtt.Client, axis: str, data: bytes,
                              retained: bool) -> None:
        if axis not in self.machine.axes:
            log.warning("Sparkplug: DCMD for %r, not a device of this node: ignored", axis)
            return
        command = None
        try:
            command = self.gate.admit(axis, data, retained)
            await self.commander.run(self.user, command, "sparkplug", OWNER)
            result: Metrics = {RESULT: (STRING, "Good"), RESULT_ERROR: (STRING, "")}
        except Refused as exc:
            if command is None:  # refused before the commander (which logs its own)
                suffix = self.commander.refusals.admit("sparkplug gate")
                if suffix is not None:  # one line per spell (servobus.gateway.refusals)
                    log.warning("Sparkplug: DCMD for %s refused (%s): %s%s", axis, exc.code,
                                exc.message, suffix)
            result = {RESULT: (STRING, exc.code), RESULT_ERROR: (STRING, exc.message)}
        # always sent, a repeated result too: each DCMD gets its answer
        self._sent.setdefault(axis, {}).update(result)
        await self._send(client, "DDATA", axis, payload(result, None))
