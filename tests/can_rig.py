"""One scripted CAN port for every test that puts a client on a fake CAN medium.

``ScriptedCanPort(script)`` is a :class:`~servobus.transport.can_bus.FramePort`. It records
each frame a client hands to ``send`` (``sent``: (identifier, data), also those
refused) and delivers the frames
``script(identifier, data)`` returns as its answer: ``(identifier, data)`` right after
``send`` returns, ``(identifier, data, delay_s)`` that much later. ``push(identifier, data)``
delivers a frame nobody asked for (an alarm, another host's reply). A script knows the
protocol (a virtual drive's ``handle_raw``, a codec); the port knows only frames.

Options, each for a medium the clients must cope with:

* ``push_mode`` (default): frames go to the receiver the client registers
  (``set_receiver``, the clients' fast path); ``push_mode=False`` has no ``set_receiver``,
  and the client calls ``recv`` (the path of a third-party port).
* ``in_order``: a frame is never delivered before one scripted earlier, however short its
  delay - one drive answering on one bus; without it a delayed frame may be overtaken.
* ``send_error``: ``send`` raises it (a medium that broke under the client), ``send_s``: a
  send takes this long (a slow adapter).

After ``close``, ``send`` and ``recv`` raise ConnectionLost and the receiver is told (None),
as a real port does.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable

from servobus.errors import ConnectionLost
from servobus.transport.base import Direction
from servobus.transport.can_bus import CanFrame, FrameReceiver, FrameTraceHook

#: One frame a script answers with: (identifier, data) at once, or (identifier, data, delay_s).
Answer = tuple[int, bytes] | tuple[int, bytes, float]
Script = Callable[[int, bytes], Iterable[Answer]]


def silent(arbitration_id: int, data: bytes) -> list[Answer]:
    """A script for a bus where nothing answers."""
    return []


class ScriptedCanPort:
    """A FramePort whose answers a test scripts (module docstring)."""

    def __init__(self, script: Script = silent, *, push_mode: bool = True,
                 in_order: bool = False, send_error: BaseException | None = None,
                 send_s: float = 0.0) -> None:
        self.script = script
        self.push_mode = push_mode
        self.in_order = in_order
        self.send_error = send_error
        self.send_s = send_s
        self.sent: list[tuple[int, bytes]] = []
        self.closed = False
        self._receiver: FrameReceiver | None = None
        self._queue: asyncio.Queue[CanFrame | None] = asyncio.Queue()
        self._traces: list[FrameTraceHook] = []
        self._last_at = 0.0  # loop time of the latest scheduled delivery (in_order)
        if push_mode:  # only then: a port without set_receiver is read with recv
            self.set_receiver = self._set_receiver

    def _set_receiver(self, receiver: FrameReceiver) -> None:
        self._receiver = receiver

    def add_trace(self, hook: FrameTraceHook) -> None:
        self._traces.append(hook)

    async def send(self, arbitration_id: int, data: bytes) -> None:
        frame = (arbitration_id, bytes(data))
        self.sent.append(frame)  # even if refused below: a test sees every attempt
        if self.closed:
            raise ConnectionLost("scripted CAN port closed")
        if self.send_error is not None:
            raise self.send_error
        if self.send_s:
            await asyncio.sleep(self.send_s)  # scripted: a send that takes this long
        self._trace(Direction.TX, CanFrame(*frame))
        loop = asyncio.get_running_loop()
        for answer in self.script(*frame):
            identifier, payload = answer[0], bytes(answer[1])
            delay = answer[2] if len(answer) == 3 else 0.0  # type: ignore[misc]
            if self.in_order:
                self._last_at = max(self._last_at, loop.time() + delay)
                loop.call_at(self._last_at, self.push, identifier, payload)
            elif delay:
                loop.call_later(delay, self.push, identifier, payload)
            else:
                loop.call_soon(self.push, identifier, payload)

    def push(self, arbitration_id: int, data: bytes) -> None:
        """Deliver one frame now, as if it came from the bus (dropped once closed)."""
        if self.closed:
            return
        frame = CanFrame(arbitration_id, bytes(data))
        self._trace(Direction.RX, frame)
        if self.push_mode:
            assert self._receiver is not None, "the client registered no receiver"
            self._receiver(frame)
        else:
            self._queue.put_nowait(frame)

    async def recv(self, timeout: float | None = None) -> CanFrame | None:
        if self.push_mode:
            raise NotImplementedError("push mode: frames go to the receiver")
        if self.closed and self._queue.empty():
            raise ConnectionLost("scripted CAN port closed")
        try:
            frame = await asyncio.wait_for(self._queue.get(), timeout)
        except TimeoutError:
            return None
        if frame is None:
            raise ConnectionLost("scripted CAN port closed")
        return frame

    async def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self._receiver is not None:
            self._receiver(None)
        self._queue.put_nowait(None)

    def _trace(self, direction: Direction, frame: CanFrame) -> None:
        now = time.monotonic()
        for hook in self._traces:
            hook(direction, frame, now)
