"""Publish a machine to an MQTT broker (aiomqtt) and, when allowed, take commands from it.

Topics (``<m>`` the machine's name, ``<a>`` an axis's name)::

    servobus/<m>/status        "online" / "offline" (retained; "offline" is the last will)
    servobus/<m>/link          JSON when a link goes down or comes back (QoS 1, not retained)
    servobus/<m>/status/seq    the birth sequence and heartbeat (servobus.gateway.mqtt_presence)
    servobus/<m>/<a>/state     JSON every 1/rate s: position, speed, current, unit, moving,
                               enabled, in_position, alarm (code), alarm_text, ok, error,
                               online, last_good, power_lost, power_lost_reason,
                               interrupted, time
    servobus/<m>/<a>/alarm     JSON {"code", "text", "time"} when it changes (retained)
    servobus/<m>/<a>/cmd       commands (only with --mqtt-commands; servobus.gateway.mqtt_gate)
    servobus/<m>/<a>/reply     {"id", "ok", "code", "error"} for each command

Decisions: with commands, MQTT 5 (Mosquitto, EMQX, HiveMQ, ... all speak it): its
subscription option "retain as published" is what lets the gateway see that a command was
retained. Without commands MQTT 3.1.1, which every broker speaks and which costs paho less
per message (no property block). State messages QoS 0 (the next one replaces a lost one),
alarms and status QoS 1 retained (a subscriber that comes later learns them), replies
QoS 1. Commands are only taken when the gateway itself logs in to the broker with a user
name and password: the broker's authentication and its ACL on ``.../cmd`` say who may
command; the gateway checks each command like an OPC UA call (servobus.gateway.commands), as user
``mqtt:<its broker user>``. A lost broker is retried every :data:`RECONNECT_S` seconds.

Link messages (issue 29): one per link change, as the OPC UA LinkEventType event; not
retained (one topic serves every link of the machine, and a retained message would keep
only the last link's; the state messages carry each axis's ``online`` for a late
subscriber). While the broker is away they wait, at most :data:`MAX_PENDING_LINK_EVENTS`
(the oldest go first), and go out with their own ``time`` when it is back.
``servobus`` is the default prefix (``--mqtt-prefix``).

Identity (issue 30, servobus.gateway.mqtt_presence): one client id per gateway,
``servobus-<gateway id>``; before each connection a probe looks for a live rival on the same
topics and the gateway does not take them over from one (at start it refuses to start).
Error boundary: each command is answered, an unexpected error as BadInternalError with one
log line; the command loop and the gateway go on.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import ssl
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn
from urllib.parse import unquote, urlparse

import aiomqtt
from paho.mqtt.subscribeoptions import SubscribeOptions

from servobus import bounded_json
from servobus.errors import InvalidValue, JsonRefused
from servobus.gateway.cancelling import cancel_until_ended, check_not_cancelled
from servobus.gateway.commands import Commander, Refused
from servobus.gateway.identity import DEFAULT_PREFIX, check_prefix, gateway_id
from servobus.gateway.link_events import LinkEvent
from servobus.gateway.mqtt_gate import DEFAULT_MAX_AGE_S, CommandGate
from servobus.gateway.mqtt_presence import Presence
from servobus.gateway.sampler import Sample, Sampler
from servobus.gateway.source import Machine

log = logging.getLogger(__name__)

DEFAULT_MQTT_RATE_HZ = 5.0
RECONNECT_S = 2.0
BAD_TOPIC_CHARS = set("+#/\0")
MAX_PENDING_LINK_EVENTS = 100


@dataclass(frozen=True)
class MqttOptions:
    url: str
    username: str | None = None
    password: str | None = None
    commands: bool = False
    rate_hz: float = DEFAULT_MQTT_RATE_HZ
    ca: Path | None = None
    cert: Path | None = None
    key: Path | None = None
    insecure: bool = False
    max_age_s: float = DEFAULT_MAX_AGE_S
    prefix: str = DEFAULT_PREFIX
    gateway_id: str | None = None  # None: the machine's name (servobus.gateway.identity)


@dataclass(frozen=True)
class Broker:
    host: str
    port: int
    tls: bool
    username: str | None
    password: str | None


def parse_broker(url: str) -> Broker:
    """``mqtt://[user[:password]@]host[:port]`` (1883) or ``mqtts://...`` (TLS, 8883)."""
    parsed = urlparse(url)
    if parsed.scheme not in ("mqtt", "mqtts") or not parsed.hostname:
        raise InvalidValue(f"{url!r}: give the broker as mqtt://HOST:PORT or "
                                 "mqtts://HOST:PORT")
    tls = parsed.scheme == "mqtts"
    try:
        port = parsed.port or (8883 if tls else 1883)
    except ValueError:
        raise InvalidValue(f"{url!r}: the port must be 1..65535") from None
    user = unquote(parsed.username) if parsed.username else None
    password = unquote(parsed.password) if parsed.password else None
    return Broker(parsed.hostname, port, tls, user, password)


def check_topic_name(kind: str, name: str) -> None:
    if not name or BAD_TOPIC_CHARS & set(name):
        raise InvalidValue(f"{kind} name {name!r} cannot be an MQTT topic level "
                           "(no '/', '+', '#')",
                           f"rename the {kind} in the machine file; nothing was sent")


def state_json(sample: Sample, unit: str) -> bytes:
    st, h = sample.status, sample.health

    def num(x: float | None) -> float | None:
        return None if x is None or not math.isfinite(x) else x

    body: dict[str, object] = {
        "position": num(sample.position), "speed": num(sample.speed),
        "current": num(sample.current), "unit": unit,
        "moving": st.moving if st else None, "enabled": st.enabled if st else None,
        "in_position": st.in_position if st else None,
        "alarm": st.alarm_code if st else None, "alarm_text": st.alarm_text if st else None,
        "ok": sample.ok, "error": sample.error or None, "online": h.online,
        "last_good": None if h.last_good is None else round(h.last_good, 3),
        "power_lost": h.power_lost, "power_lost_reason": h.power_lost_reason,
        "interrupted": h.interrupted, "time": round(sample.time, 3),
    }
    return json.dumps(body, separators=(",", ":")).encode()


def link_json(event: LinkEvent) -> bytes:
    body: dict[str, object] = {
        "url": event.url, "axes": list(event.axes), "online": event.online,
        "reason": event.reason or None,
        "last_good": None if event.last_good is None else round(event.last_good, 3),
        "power_lost": list(event.power_lost), "interrupted": list(event.interrupted),
        "time": round(event.time, 3),
    }
    return json.dumps(body, separators=(",", ":")).encode()


class MqttGateway:
    def __init__(self, machine: Machine, sampler: Sampler, commander: Commander,
                 options: MqttOptions) -> None:
        check_topic_name("machine", machine.name)
        for name in machine.axes:
            check_topic_name("axis", name)
        self.machine = machine
        self.sampler = sampler
        self.commander = commander
        self.options = options
        self.broker = parse_broker(options.url)
        self.username = broker_user(options, self.broker, "--mqtt-commands")
        self.password = options.password or self.broker.password
        self.gate = CommandGate(options.max_age_s)
        self.base = f"{check_prefix(options.prefix)}/{machine.name}"
        self.presence = Presence(self.base, gateway_id(machine.name, options.gateway_id))
        self._rival_told = self._blind_told = False  # one log line a spell
        self.published = 0
        self.connected = asyncio.Event()
        self._alarm: dict[str, tuple[int, bool]] = {}
        self._links: deque[LinkEvent] = deque(maxlen=MAX_PENDING_LINK_EVENTS)
        self._link_wake = asyncio.Event()
        sampler.link_listeners.append(self.on_link)

    def on_link(self, event: LinkEvent) -> None:
        """Sampler link listener: the event waits for the session's link task."""
        self._links.append(event)
        self._link_wake.set()

    def _tls(self) -> ssl.SSLContext | None:
        return tls_context(self.options, self.broker)

    def client(self, probe: bool = False) -> aiomqtt.Client:
        """The gateway's connection (its client id, its will), or a probe's."""
        p = self.presence
        return broker_client(self.options, p.probe_id() if probe else p.client_id,
                             None if probe else p.will())

    async def run(self) -> None:
        """Publish until cancelled; reconnects after a lost broker. GatewayConflict when a
        live gateway serves the topics before this one ever did."""
        await keep_connected(self._connect, self.connected, "MQTT broker", self.broker, log)

    async def _connect(self) -> None:
        if not await self.claim():
            await asyncio.sleep(RECONNECT_S)
            return
        async with self.client() as client:
            await self._session(client)

    async def _session(self, client: aiomqtt.Client) -> None:
        await self.presence.birth(client)
        self._alarm.clear()
        log.info("MQTT: publishing %s/... to %s:%s%s", self.base, self.broker.host,
                 self.broker.port, " (commands on)" if self.options.commands else "")
        tasks = [asyncio.create_task(self._publish_loop(client)),
                 asyncio.create_task(self._link_loop(client))]
        if self.options.commands:
            # MQTT 5 "retain as published": a retained command keeps its flag on the way
            # to a live subscriber too, so it is refused now and not only on a replay
            await client.subscribe(f"{self.base}/+/cmd", options=SubscribeOptions(
                qos=1, retainAsPublished=True))
            tasks.append(asyncio.create_task(self._command_loop(client)))
        tasks.append(asyncio.create_task(self.presence.beat(client)))
        self.connected.set()
        await run_session(tasks, lambda: self.say_offline(client))

    async def say_offline(self, client: aiomqtt.Client) -> None:
        await client.publish(f"{self.base}/status", b"offline", qos=1, retain=True)

    async def _publish_loop(self, client: aiomqtt.Client) -> None:
        period = 1.0 / self.options.rate_hz
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        paho = paho_of(client)
        while True:
            for name, axis in self.machine.axes.items():
                sample = self.sampler.latest.get(name)
                if sample is None:
                    continue
                await self._send_state(client, paho, f"{self.base}/{name}/state",
                                       state_json(sample, axis.unit))
                self.published += 1
                await self._alarm_change(client, sample)
            next_at = max(next_at + period, loop.time())
            await asyncio.sleep(next_at - loop.time())

    @staticmethod
    async def _send_state(client: aiomqtt.Client, paho: object, topic: str,
                          payload: bytes) -> None:
        """A QoS 0 state message. aiomqtt's publish waits until paho reports each message
        written (one event-loop round trip per message; at 32 axes x 50 Hz that was a
        quarter of the gateway's CPU): a state message is handed to aiomqtt's paho client,
        whose socket aiomqtt drives, without that wait. Alarms, status and replies keep
        the awaited publish."""
        publish = getattr(paho, "publish", None)
        if publish is None:
            await client.publish(topic, payload)
            return
        info = publish(topic, payload, 0, False)
        if info.rc != 0:  # the connection is gone: let aiomqtt raise and reconnect
            await client.publish(topic, payload)

    async def _link_loop(self, client: aiomqtt.Client) -> None:
        """Each link event once, QoS 1; one that could not be sent waits for the next
        session."""
        if self._links:
            self._link_wake.set()
        while True:
            await self._link_wake.wait()
            self._link_wake.clear()
            while self._links:
                event = self._links.popleft()
                try:
                    await client.publish(f"{self.base}/link", link_json(event), qos=1)
                except BaseException:  # the broker is gone (or we stop): keep it for later
                    self._links.appendleft(event)
                    raise

    async def _alarm_change(self, client: aiomqtt.Client, sample: Sample) -> None:
        st = sample.status
        if not sample.ok or st is None:
            return
        key = (st.alarm_code, True)
        if self._alarm.get(sample.axis) == key:
            return
        self._alarm[sample.axis] = key
        body = {"code": st.alarm_code, "text": st.alarm_text, "time": round(sample.time, 3)}
        await client.publish(f"{self.base}/{sample.axis}/alarm", json.dumps(body).encode(),
                             qos=1, retain=True)

    async def _command_loop(self, client: aiomqtt.Client) -> None:
        async for message in client.messages:
            parts = message.topic.value.split("/")
            if len(parts) != 4 or parts[3] != "cmd":
                continue
            axis = parts[2]
            payload = message.payload if isinstance(message.payload, bytes) else \
                str(message.payload).encode()
            await self._answer(client, axis, payload, bool(message.retain))

    async def _command(self, client: aiomqtt.Client, axis: str, payload: bytes,
                       retained: bool) -> None:
        ident: str | None = None
        try:
            accepted = self.gate.admit(axis, payload, retained)
            ident = accepted.id
            await self.commander.run(f"mqtt:{self.username}", accepted.command, "mqtt",
                                     accepted.owner)
            reply: dict[str, object] = {"id": ident, "ok": True, "code": "Good"}
        except Refused as exc:
            if ident is None:
                ident = _peek_id(payload)
                suffix = self.commander.refusals.admit("mqtt gate")
                if suffix is not None:  # one line per spell (servobus.gateway.refusals)
                    log.warning("mqtt: command on %s/%s/cmd refused (%s): %s%s", self.base,
                                axis, exc.code, exc.message, suffix)
            reply = {"id": ident, "ok": False, "code": exc.code, "error": exc.message}
        await client.publish(f"{self.base}/{axis}/reply", json.dumps(reply).encode(), qos=1)

    async def _answer(self, client: aiomqtt.Client, axis: str, payload: bytes,
                      retained: bool) -> None:
        """One command in its own error boundary: an unexpected error is answered
        BadInternalError with one log line, and the next command is read. A lost broker
        (MqttError) still ends the session, to reconnect."""
        try:
            await self._command(client, axis, payload, retained)
        except (aiomqtt.MqttError, asyncio.CancelledError):
            raise
        except Exception as exc:
            log.error("mqtt: command on %s/%s/cmd failed unexpectedly: %s: %s", self.base,
                      axis, type(exc).__name__, exc)
            reply = {"id": _peek_id(payload), "ok": False, "code": "BadInternalError",
                     "error": f"internal error ({type(exc).__name__}), in the gateway's log"}
            await client.publish(f"{self.base}/{axis}/reply", json.dumps(reply).encode(),
                                 qos=1)

    async def claim(self) -> bool:
        """Probe the broker before taking the client id: True when the topics are free
        (the next birth's number taken); False, one log line a spell, while a live gateway
        serves them after this one did; GatewayConflict when this one never served them."""
        seen = await self.presence.probe(self.client(probe=True))
        if not seen.checked and not self._blind_told:
            log.warning("MQTT: the broker refused this gateway's subscription to %s/status/#: "
                        "connecting without looking for a rival gateway on these topics",
                        self.base)
        self._blind_told = not seen.checked
        if self.presence.free(seen):
            self._rival_told = False
            return True
        conflict = self.presence.conflict(seen, f"{self.broker.host}:{self.broker.port}")
        if self.presence.births == 0:
            raise conflict
        if not self._rival_told:
            self._rival_told = True
            log.error("%s; checking again every %g s", conflict, RECONNECT_S)
        return False


def broker_user(options: MqttOptions, broker: Broker, commands_option: str) -> str | None:
    """The gateway's broker login name; InvalidValue when commands are on without a login
    (``commands_option`` names what turned them on)."""
    username = options.username or broker.username
    if options.commands and not (username and (options.password or broker.password)):
        raise InvalidValue(f"{commands_option} needs the broker's authentication: "
                           "give --mqtt-user and a password")
    return username


async def keep_connected(connect: Callable[[], Awaitable[None]], connected: asyncio.Event,
                         who: str, broker: Broker, logger: logging.Logger) -> NoReturn:
    """``connect`` (one session) again RECONNECT_S after each lost broker, one warning on
    ``logger`` for each loss (``who`` begins it)."""
    while True:
        check_not_cancelled()  # a stop swallowed by the last session's aiomqtt call
        try:
            await connect()
        except aiomqtt.MqttError as exc:
            connected.clear()
            logger.warning("%s %s:%s: %s; retrying in %g s", who, broker.host, broker.port,
                           exc, RECONNECT_S)
            await asyncio.sleep(RECONNECT_S)


async def run_session(tasks: list[asyncio.Task[None]],
                      farewell: Callable[[], Awaitable[None]]) -> None:
    """A connection's tasks until one fails (a lost broker ends the session); then all are
    cancelled and ``farewell`` (the offline message: a clean stop sends no will) gets 1 s.
    The tasks are cancelled until they end, and a stop that the connection's set-up
    swallowed ends the session before it waits (servobus.gateway.cancelling)."""
    try:
        check_not_cancelled()
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
        for task in done:
            task.result()
    finally:
        await cancel_until_ended(tasks)
        with contextlib.suppress(Exception):
            async with asyncio.timeout(1.0):
                await farewell()


def tls_context(o: MqttOptions, broker: Broker) -> ssl.SSLContext | None:
    if not (broker.tls or o.ca or o.cert):
        return None
    ctx = ssl.create_default_context(cafile=str(o.ca) if o.ca else None)
    if o.cert:
        ctx.load_cert_chain(str(o.cert), str(o.key) if o.key else None)
    if o.insecure:
        ctx.check_hostname = False
        ctx.verify_mode = ssl.CERT_NONE
    return ctx


def paho_of(client: aiomqtt.Client) -> object:
    """The aiomqtt client's paho client (an MQTT client, not a drive's), or None: what
    :meth:`MqttGateway._send_state` hands QoS 0 state messages to without a round trip."""
    return getattr(client, "_client", None)


def broker_client(options: MqttOptions, identifier: str,
                  will: aiomqtt.Will | None) -> aiomqtt.Client:
    """A connection to the options' broker with the gateway's login."""
    broker = parse_broker(options.url)
    return aiomqtt.Client(
        broker.host, broker.port, username=options.username or broker.username,
        password=options.password or broker.password, identifier=identifier, will=will,
        tls_context=tls_context(options, broker), timeout=5.0, keepalive=10,
        protocol=(aiomqtt.ProtocolVersion.V5 if options.commands
                  else aiomqtt.ProtocolVersion.V311))


async def check_topics_free(options: MqttOptions, machine_name: str) -> None:
    """Before the machine is opened: GatewayConflict when a live gateway serves its topics.
    A broker that cannot be reached now is no refusal (the gateway checks again each time
    it connects)."""
    check_topic_name("machine", machine_name)
    base = f"{check_prefix(options.prefix)}/{machine_name}"
    presence = Presence(base, gateway_id(machine_name, options.gateway_id))
    try:
        seen = await presence.probe(broker_client(options, presence.probe_id(), None))
    except aiomqtt.MqttError:
        return
    if not presence.free(seen):
        broker = parse_broker(options.url)
        raise presence.conflict(seen, f"{broker.host}:{broker.port}")


def _peek_id(payload: bytes) -> str | None:
    try:
        data = bounded_json.loads(payload)
    except JsonRefused:
        return None
    ident = data.get("id") if isinstance(data, dict) else None
    return ident[:128] if isinstance(ident, str) else None
