"""A Sparkplug B observer for the tests: an aiomqtt subscription to ``spBv1.0/<group>/#``
whose messages are decoded with the independent Tahu classes (tahu_rig) and kept in order."""

from __future__ import annotations

import asyncio
import contextlib
import uuid
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

import aiomqtt
from gateway_rig import BROKER_USERS
from rig import wait_until_async
from tahu_rig import decode


@dataclass
class Message:
    topic: str
    kind: str  # NBIRTH, DDATA, ...
    node: str
    device: str | None
    payload: Any  # the Tahu Payload; None for a STATE or an undecodable one
    retain: bool


class Observer:
    def __init__(self, client: aiomqtt.Client) -> None:
        self.client = client
        self.messages: list[Message] = []

    async def _read(self) -> None:
        async for message in self.client.messages:
            parts = message.topic.value.split("/")
            data = message.payload if isinstance(message.payload, bytes) else b""
            self.messages.append(Message(message.topic.value, parts[2], parts[3],
                                         parts[4] if len(parts) > 4 else None, decode(data),
                                         bool(message.retain)))

    def of(self, kind: str, node: str | None = None, device: str | None = None
           ) -> list[Message]:
        return [m for m in self.messages if m.kind == kind and node in (None, m.node)
                and device in (None, m.device)]

    async def until(self, test: Callable[[], object], what: str,
                    timeout: float = 30.0) -> None:
        async def check() -> bool:
            return bool(test())
        await wait_until_async(check, timeout=timeout, what=what)

    async def publish(self, topic: str, payload: bytes, retain: bool = False) -> None:
        await self.client.publish(topic, payload, qos=1, retain=retain)


@contextlib.asynccontextmanager
async def observing(port: int, group: str) -> AsyncIterator[Observer]:
    """An observer subscribed to the group's topics (as user tester) while in the block."""
    client = aiomqtt.Client("127.0.0.1", port, username="tester",
                            password=BROKER_USERS["tester"],
                            identifier=f"spb-observer-{uuid.uuid4().hex[:8]}")
    async with client:
        await client.subscribe(f"spBv1.0/{group}/#", qos=1)
        observer = Observer(client)
        reader = asyncio.create_task(observer._read())
        try:
            yield observer
        finally:
            reader.cancel()
            await asyncio.gather(reader, return_exceptions=True)
