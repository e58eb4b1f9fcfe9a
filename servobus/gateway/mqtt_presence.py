"""The gateway's presence on its broker: a birth/death sequence, a heartbeat, and a look for
a live rival before it takes its client id.

Topics (``<base>`` is ``<prefix>/<machine>``)::

    <base>/status        "online" / "offline", retained, QoS 1; "offline" is the last will
    <base>/status/seq    {"seq", "gateway", "since", "time"}, retained; the birth sequence
                         of the connection that published "online", republished every
                         HEARTBEAT_S seconds while it lives (its heartbeat)

Decisions (docs/gateway.md "Identity", issue 30):

* **One client id** per gateway, ``servobus-<gateway id>`` (servobus.gateway.identity).
  A broker accepts a connection with a client id only after it closed the older one with
  that id, and publishes the older one's will (if at all) then: a reconnecting gateway
  replaces its own half-open connection, whose will can no longer come later and overwrite
  the new ``online`` (it did at +15 s with a client id drawn at random per connection).
* **The birth/death sequence** (as Sparkplug's bdSeq) travels in ``<base>/status/seq``,
  beside ``status``, whose payload stays ``online``/``offline`` for existing subscribers.
  Each connection's birth takes the next number (the retained one plus one; 0 on a new
  broker) and publishes it before ``online``. A death (``offline``, the will or a clean
  stop) belongs to the seq retained when it arrives: with one client id the will of
  connection N is published before connection N+1 is accepted, so before birth N+1.
* **A rival** is another live gateway on the same topics (same prefix and machine name).
  Before each connection with the shared client id (which would close the rival's), a
  probe connection with a client id of its own reads the retained ``status`` and ``seq``
  (the SUBACK of a second subscription, to ``<base>/status/probe`` where nobody publishes,
  comes after the retained messages of the first: it marks their end; the probe needs
  nothing but leave to subscribe to ``<base>/status/#``). The topics are free when
  ``status`` is not ``online``, or when
  the retained seq is this process's own last birth (a reconnect). Otherwise the probe
  waits up to :data:`LIVENESS_S` for a heartbeat published live: one comes from a live
  rival (refused: :class:`~servobus.errors.GatewayConflict`); none comes when the
  ``online`` is the leftover of a gateway that crashed or lost its network and whose
  connection the broker has not yet given up (its will has not fired yet): taken over.
  A gateway killed outright (its socket closed by the kernel) left ``offline`` already:
  its restart is not delayed at all.
* A broker that refuses the probe's subscriptions (its ACL) leaves the check undone: the
  gateway connects without it (it must not stop serving for want of a safety net) and
  says so in one log line.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import secrets
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import aiomqtt

from servobus import bounded_json
from servobus.errors import GatewayConflict, JsonRefused
from servobus.gateway.identity import client_id

log = logging.getLogger(__name__)

HEARTBEAT_S = 1.0
#: A live gateway's heartbeat comes at least this often (3 beats; a loaded machine may be
#: late by a beat or two).
LIVENESS_S = 3.0
ONLINE, OFFLINE = b"online", b"offline"
MAX_SEQ_PAYLOAD = 512


@dataclass(frozen=True)
class Seen:
    """What a probe found on the broker."""

    status: bytes | None  # the retained status, None when there is none
    seq: int | None  # the retained birth sequence
    gateway: str = ""  # the gateway id that published it
    since: float | None = None  # when that birth was (its gateway's clock)
    live: bool = False  # a heartbeat was published while the probe listened
    checked: bool = True  # False: the broker refused the probe's subscriptions


def parse_seq(payload: bytes) -> tuple[int, str, float | None] | None:
    """``<base>/status/seq``'s (seq, gateway, since), or None when it is not one (anyone the
    broker lets publish there may write anything)."""
    if len(payload) > MAX_SEQ_PAYLOAD:
        return None
    try:
        data = bounded_json.loads(payload)
    except JsonRefused:
        return None
    if not isinstance(data, dict):
        return None
    seq, gateway, since = data.get("seq"), data.get("gateway"), data.get("since")
    if isinstance(seq, bool) or not isinstance(seq, int) or seq < 0:
        return None
    ok_since = isinstance(since, int | float) and not isinstance(since, bool)
    return seq, gateway if isinstance(gateway, str) else "", since if ok_since else None


class Presence:
    """One gateway's birth, heartbeat and rival check on the topics under ``base``."""

    def __init__(self, base: str, ident: str) -> None:
        self.base = base
        self.ident = ident
        self.client_id = client_id(ident)
        self.status_topic = f"{base}/status"
        self.seq_topic = f"{base}/status/seq"
        self.seq: int | None = None  # this process's last birth
        self.births = 0
        self._next = 0
        self._since = 0.0

    def probe_id(self) -> str:
        """A client id of the probe's own: it must not close the connection it looks for."""
        return f"{self.client_id}-probe-{secrets.token_hex(4)}"

    def will(self) -> aiomqtt.Will:
        return aiomqtt.Will(self.status_topic, OFFLINE, qos=1, retain=True)

    # ------------------------------------------------------------ before connecting
    async def probe(self, client: aiomqtt.Client) -> Seen:
        """Read the retained status and seq through ``client`` (a connection of its own; it
        is closed here), and listen for a live heartbeat when that decides."""
        status: bytes | None = None
        seq: tuple[int, str, float | None] | None = None
        live = False
        async with client:
            granted = await client.subscribe([(self.status_topic, 1), (self.seq_topic, 1)])
            marker = await client.subscribe(f"{self.base}/status/probe", qos=1)
            if _refused(granted) or _refused(marker):
                return Seen(None, None, checked=False)
            for _ in range(len(client.messages)):  # the retained ones, all in by now
                message = await anext(client.messages)
                topic, payload = message.topic.value, _payload(message.payload)
                if topic == self.status_topic:
                    status = payload
                elif topic == self.seq_topic:
                    seq = parse_seq(payload) or seq
                    live = live or not message.retain
            if status == ONLINE and not live and not self._own(seq):
                status, live = await self._listen(client, status)
        number, gateway, since = seq if seq is not None else (None, "", None)
        return Seen(status, number, gateway, since, live)

    async def _listen(self, client: aiomqtt.Client, status: bytes) -> tuple[bytes, bool]:
        """Up to LIVENESS_S for a heartbeat (live: True) or a new status."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(LIVENESS_S):
                async for message in client.messages:
                    topic = message.topic.value
                    if topic == self.seq_topic and not message.retain:
                        return status, True
                    if topic == self.status_topic:
                        status = _payload(message.payload)
                        if status != ONLINE:
                            return status, False
        return status, False

    def _own(self, seq: tuple[int, str, float | None] | None) -> bool:
        return seq is not None and self.seq is not None and seq[0] == self.seq \
            and seq[1] == self.ident

    def free(self, seen: Seen) -> bool:
        """Whether the topics are free for this gateway (no live rival in ``seen``); when
        they are, the next birth's number follows the one seen (and this process's own)."""
        if seen.checked and seen.status == ONLINE and seen.live:
            return False
        after = -1 if seen.seq is None else seen.seq
        self._next = max(after, -1 if self.seq is None else self.seq) + 1
        return True

    def conflict(self, seen: Seen, broker: str) -> GatewayConflict:
        since = "" if seen.since is None else \
            f", online since {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(seen.since))}"
        return GatewayConflict(
            f"MQTT topics {self.base}/... on broker {broker} are served by a live gateway "
            f"(gateway id {seen.gateway or '?'}, birth {seen.seq}{since}); this one did not "
            "take them over - stop that gateway, or serve this machine under another "
            "--mqtt-prefix or machine name")

    # ------------------------------------------------------------ connected
    async def birth(self, client: aiomqtt.Client) -> None:
        """The next sequence number, then ``online`` (both retained, QoS 1)."""
        self.seq = self._next
        self._next += 1
        self.births += 1
        self._since = time.time()
        await client.publish(self.seq_topic, self._seq_json(), qos=1, retain=True)
        await client.publish(self.status_topic, ONLINE, qos=1, retain=True)

    async def beat(self, client: aiomqtt.Client,
                   sleep: Callable[[float], Awaitable[None]] = asyncio.sleep) -> None:
        """The heartbeat: the seq again, every HEARTBEAT_S, until cancelled."""
        while True:
            await sleep(HEARTBEAT_S)
            await client.publish(self.seq_topic, self._seq_json(), qos=0, retain=True)

    def _seq_json(self) -> bytes:
        body = {"seq": self.seq, "gateway": self.ident, "since": round(self._since, 3),
                "time": round(time.time(), 3)}
        return json.dumps(body, separators=(",", ":")).encode()


def _refused(granted: object) -> bool:
    """Whether a SUBACK refused a topic (MQTT 3.1.1: granted QoS 128; MQTT 5: a reason
    code of 128 or more)."""
    codes = granted if isinstance(granted, list | tuple) else [granted]
    return any(getattr(code, "is_failure", False) is True
               or (isinstance(code, int) and code >= 128) for code in codes)


def _payload(payload: object) -> bytes:
    if isinstance(payload, bytes):
        return payload
    return b"" if payload is None else str(payload).encode()
