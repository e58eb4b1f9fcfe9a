"""The gateway's faults of issue 30: hostile MQTT payloads, OPC UA session floods, login floods.

Each function runs one fault kind against a running gateway (``servobus serve``, or a
:class:`servobus.gateway.serve.Gateway` in this process) and returns a small dict of what
it did and what it saw: ``kind``, counts, ``serving`` (the gateway still answered what a
well-behaved client asks afterwards) and ``seconds``. The fault run of
``python -m benchmarks faults`` calls them; tests/gateway runs them with small counts.

* :func:`hostile_mqtt` (the gateway must take commands, ``--mqtt-commands``; the sender
  needs the broker's leave to publish on ``.../cmd``): :func:`hostile_payloads` (seeded:
  the three of issue 30 - a 400-digit ``value``, a 400-digit ``ts``, 4 KB nested 1,000
  deep - then random bytes, broken and deep JSON, numbers beyond a double, wrong types,
  oversize payloads, commands on axes that do not exist) on ``<base>/<axis>/cmd``, at most
  ``window`` unanswered at a time (a broker drops what a slow subscriber's queue cannot
  hold); every one must be answered on ``.../reply``. None of them can move an axis (no
  fresh ``ts``); some are plain stops. The gateway answers one command after the other,
  each after its reply's QoS 1 round trip: about 90 a second on the 2-core machine at
  load 6 (10,000 in about 2 minutes; 300 in about 3 s).
* :func:`session_flood`: anonymous OPC UA sessions from one address, each asking for more
  subscriptions than its cap, until the caps refuse; then a client from another address
  must still get a session, a subscription and a value.
* :func:`login_flood`: wrong passwords from one address, then the right one from another,
  which must get its session.

OPC UA clients are bound to a source address (127.0.0.2, ...: all of 127.0.0.0/8 is
loopback on Linux) so that the gateway's per-address limits see separate clients.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import random
import time
import uuid
from collections import Counter
from typing import Any

#: The three payloads of issue 30 that killed the gateway.
DIGITS_400 = "1" + "0" * 399
VALUE_400 = ('{"cmd":"stop","value":' + DIGITS_400 + "}").encode()
TS_400 = ('{"cmd":"stop","ts":' + DIGITS_400 + "}").encode()
MAX_PAYLOAD = 4096  # servobus.gateway.mqtt_gate.MAX_PAYLOAD: the nested one fits it


def nested_4k() -> bytes:
    """A 4,096-byte command whose value is nested 1,000 deep."""
    head, tail = '{"cmd":"stop","pad":"', '","value":' + "[" * 1000 + "]" * 1000 + "}"
    return (head + "x" * (MAX_PAYLOAD - len(head) - len(tail)) + tail).encode()


NAMED = (VALUE_400, TS_400)
COMMANDS = ("move_absolute", "move_relative", "set_speed", "stop", "enable", "disable",
            "reset_alarm", "fly", "", "STOP")
STALE_TS, FUTURE_TS = 1_000_000_000, 4_000_000_000  # never fresh: nothing generated moves


def _number(rng: random.Random) -> object:
    return rng.choice([
        int("9" * rng.randint(300, 500)), -int("9" * 320), 1e308, -1e308, 5e-324, 0, -0.0,
        2**63, -(2**63) - 1, 2**64, rng.uniform(-1e6, 1e6), rng.randint(-10**9, 10**9)])


def _value(rng: random.Random, depth: int = 0) -> object:
    kind = rng.randrange(9 if depth < 4 else 6)
    if kind == 0:
        return _number(rng)
    if kind == 1:
        return "".join(chr(rng.randint(0, 0x2FFF)) for _ in range(rng.randint(0, 40)))
    if kind == 2:
        return "x" * rng.randint(100, 3000)
    if kind == 3:
        return rng.choice([True, False, None])
    if kind == 4:
        return "\ud800"  # a lone surrogate (escaped in the JSON text)
    if kind == 5:
        return rng.choice(["NaN", "1e400", "", " ", "\x00", "stop"])
    if kind == 6:
        return [_value(rng, depth + 1) for _ in range(rng.randint(0, 5))]
    return {_key(rng): _value(rng, depth + 1) for _ in range(rng.randint(0, 5))}


def _key(rng: random.Random) -> str:
    return rng.choice(["cmd", "id", "ts", "value", "ttl", "client", "", "x" * 200, "\u00e9"])


def _command(rng: random.Random) -> bytes:
    """An almost-command: real field names, never a fresh ts."""
    body: dict[str, object] = {"cmd": rng.choice(COMMANDS)}
    for key in ("id", "ts", "value", "ttl", "client"):
        if rng.random() < 0.6:
            body[key] = _value(rng)
    if rng.random() < 0.5:
        body["ts"] = rng.choice([STALE_TS, FUTURE_TS, DIGITS_400, "now", None])
    text = json.dumps(body)
    if rng.random() < 0.3:  # numbers no double holds, written as JSON text
        text = text.replace("}", ', "value": ' + rng.choice(["1e400", "-1e999", DIGITS_400,
                                                              "NaN", "Infinity"]) + "}", 1)
    return text.encode()


def _deep(rng: random.Random) -> bytes:
    depth = rng.choice([30, 32, 33, 40, 200, 1000, 1500])
    opener, closer = rng.choice([("[", "]"), ('{"a":', "}")])
    return (f'{{"cmd":"stop","value":{opener * depth}1{closer * depth}}}').encode()


def _broken(rng: random.Random) -> bytes:
    good = _command(rng)
    return rng.choice([good[: rng.randint(0, len(good))], b"\xef\xbb\xbf" + good,
                       b"{" * rng.randint(1, 5000), b"]" * 50, b"null", b"[]", b'"stop"',
                       b"NaN", b"1e400", b"\xff\xfe\x00", b"", b" " * 4096,
                       good.replace(b'"', b"'")])


def _noise(rng: random.Random) -> bytes:
    return rng.randbytes(rng.randint(0, 600))


def _oversize(rng: random.Random) -> bytes:
    return b'{"cmd":"stop","pad":"' + b"x" * rng.randint(MAX_PAYLOAD, 3 * MAX_PAYLOAD) + b'"}'


MAKERS = (_command, _command, _command, _deep, _broken, _broken, _noise, _oversize)


def hostile_payloads(count: int, seed: int = 30) -> list[bytes]:
    """``count`` hostile payloads, the same for the same seed: the three of issue 30 first."""
    rng = random.Random(seed)
    out = [*NAMED, nested_4k()]
    while len(out) < count:
        out.append(rng.choice(MAKERS)(rng))
    return out[:count]


# ---------------------------------------------------------------- MQTT
async def hostile_mqtt(host: str, port: int, username: str | None, password: str | None,
                       base: str, axis: str, *, count: int = 10_000, seed: int = 30,
                       window: int = 64, timeout: float = 120.0) -> dict[str, Any]:
    """Send ``count`` hostile payloads to ``<base>/<axis>/cmd`` (a few to axes that do not
    exist) and count the replies on ``<base>/+/reply``; then ask one well-formed question
    (a command it must refuse for its value) and read the retained status."""
    import aiomqtt

    rng = random.Random(seed + 1)
    payloads = hostile_payloads(count, seed)
    codes: Counter[str] = Counter()
    answered = 0
    progress = asyncio.Event()
    probe_id = f"probe-{uuid.uuid4().hex}"
    probe_reply: dict[str, Any] = {}
    start = time.monotonic()
    quiet = logging.getLogger(f"{__name__}.mqtt")  # not one warning per publish in flight
    quiet.setLevel(logging.ERROR)
    async with aiomqtt.Client(host, port, username=username, password=password,
                              identifier=f"hostile-{uuid.uuid4().hex[:12]}",
                              logger=quiet) as client:
        await client.subscribe(f"{base}/+/reply", qos=1)

        async def read() -> None:
            nonlocal answered
            async for message in client.messages:
                try:
                    reply = json.loads(message.payload if isinstance(message.payload, bytes)
                                       else b"")
                except ValueError:
                    reply = {}
                if isinstance(reply, dict) and reply.get("id") == probe_id:
                    probe_reply.update(reply)
                else:
                    answered += 1
                    codes[str(reply.get("code")) if isinstance(reply, dict) else "?"] += 1
                progress.set()

        reader = asyncio.create_task(read())
        sent = 0
        publishing: set[asyncio.Task[None]] = set()  # not one broker round trip per payload
        try:
            async with asyncio.timeout(timeout):
                for payload in payloads:
                    while sent - answered >= window:
                        progress.clear()
                        await progress.wait()
                    target = axis if rng.random() < 0.97 else rng.choice(["nosuch", "\u00fc"])
                    task = asyncio.create_task(
                        client.publish(f"{base}/{target}/cmd", payload, qos=1))
                    publishing.add(task)
                    task.add_done_callback(publishing.discard)
                    sent += 1
                await asyncio.gather(*publishing)
                while answered < sent:
                    progress.clear()
                    await progress.wait()
                probe = {"id": probe_id, "ts": time.time(), "cmd": "move_absolute",
                         "value": "far"}
                await client.publish(f"{base}/{axis}/cmd", json.dumps(probe), qos=1)
                while not probe_reply:
                    progress.clear()
                    await progress.wait()
        except TimeoutError:
            pass
        finally:
            for task in (*publishing, reader):
                task.cancel()
            await asyncio.gather(*publishing, reader, return_exceptions=True)
        seconds = time.monotonic() - start
        status = await _retained(client, f"{base}/status")
    return {"kind": "hostile mqtt", "sent": sent, "answered": answered,
            "codes": dict(codes.most_common()), "serving": probe_reply.get("code") ==
            "BadInvalidArgument" and status == b"online", "seconds": round(seconds, 2)}


async def _retained(client: Any, topic: str, wait: float = 10.0) -> bytes | None:
    await client.subscribe(topic, qos=1)
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(wait):
            async for message in client.messages:
                if message.topic.value == topic:
                    payload: bytes = message.payload if isinstance(message.payload, bytes) \
                        else b""
                    return payload
    return None


# ---------------------------------------------------------------- OPC UA
def bound_client(endpoint: str, source: str, timeout: float = 10.0) -> Any:
    """An asyncua client whose connections start from ``source`` (asyncua's client cannot
    choose its address: its one ``loop.create_connection`` call is given ``local_addr``
    while it connects; connect these clients one after another)."""
    from asyncua import Client

    client = Client(endpoint, timeout=timeout)
    uaclient = client.uaclient
    connect_socket = uaclient.connect_socket

    async def from_source(host: str, port: int) -> None:
        loop = asyncio.get_running_loop()
        loop.create_connection = functools.partial(  # type: ignore[method-assign]
            type(loop).create_connection, loop, local_addr=(source, 0))
        try:
            await connect_socket(host, port)
        finally:
            del loop.create_connection  # type: ignore[method-assign]

    uaclient.connect_socket = from_source
    return client


async def _connect(client: Any) -> str:
    """"Good", or the name of the status code that refused the session."""
    from asyncua.ua.uaerrors import UaStatusCodeError

    try:
        await client.connect()
    except UaStatusCodeError as exc:
        with contextlib.suppress(Exception):
            client.disconnect_socket()
        return type(exc).__name__
    return "Good"


class _Quiet:
    def datachange_notification(self, node: object, value: object, data: object) -> None:
        pass


async def serves(endpoint: str, source: str) -> bool:
    """A session from ``source``, a subscription and a first value: the server serves."""
    from asyncua import ua

    client = bound_client(endpoint, source)
    if await _connect(client) != "Good":
        return False
    try:
        seen = asyncio.Event()

        class Handler:
            def datachange_notification(self, node: object, value: object,
                                        data: object) -> None:
                seen.set()

        subscription = await client.create_subscription(50, Handler())
        await subscription.subscribe_data_change(
            client.get_node(ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime)))
        async with asyncio.timeout(10):
            await seen.wait()
        return True
    except Exception:
        return False
    finally:
        with contextlib.suppress(Exception):
            await client.disconnect()


async def session_flood(endpoint: str, *, sessions: int = 40, subscriptions: int = 20,
                        source: str = "127.0.0.2", other: str = "127.0.0.3"
                        ) -> dict[str, Any]:
    """``sessions`` anonymous sessions from ``source``, each asking ``subscriptions``
    subscriptions, all held; then a client from ``other`` must be served."""
    from asyncua.ua.uaerrors import UaStatusCodeError

    start = time.monotonic()
    held: list[Any] = []
    refused: Counter[str] = Counter()
    got = sub_refused = 0
    try:
        for _ in range(sessions):
            client = bound_client(endpoint, source)
            outcome = await _connect(client)
            if outcome != "Good":
                refused[outcome] += 1
                continue
            held.append(client)
            for _ in range(subscriptions):
                try:
                    await client.create_subscription(500, _Quiet())
                    got += 1
                except UaStatusCodeError as exc:
                    refused[type(exc).__name__] += 1
                    sub_refused += 1
        serving = await serves(endpoint, other)
    finally:
        for client in held:
            with contextlib.suppress(Exception):
                await client.disconnect()
    return {"kind": "session flood", "sessions": sessions, "opened": len(held),
            "subscriptions": got, "subscriptions refused": sub_refused,
            "refused": dict(refused), "serving": serving,
            "seconds": round(time.monotonic() - start, 2)}


async def login_flood(endpoint: str, user: str, password: str, *, wrong: int = 12,
                      source: str = "127.0.0.2", other: str = "127.0.0.3"
                      ) -> dict[str, Any]:
    """``wrong`` wrong passwords for ``user`` from ``source``, then the right one from
    ``other``, which must get its session (and a value)."""
    start = time.monotonic()
    refused: Counter[str] = Counter()
    for _ in range(wrong):
        client = bound_client(endpoint, source)
        client.set_user(user)
        client.set_password(password + "-wrong")
        outcome = await _connect(client)
        if outcome == "Good":
            await client.disconnect()
        refused[outcome] += 1
    client = bound_client(endpoint, other)
    client.set_user(user)
    client.set_password(password)
    right = await _connect(client)
    if right == "Good":
        await client.disconnect()
    return {"kind": "login flood", "sent": wrong + 1, "refused": dict(refused),
            "right login": right, "serving": right == "Good" and await serves(endpoint, other),
            "seconds": round(time.monotonic() - start, 2)}
