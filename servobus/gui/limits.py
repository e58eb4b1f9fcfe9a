"""Bounded inputs of the GUI server: request bodies, WebSocket messages, JSON.

Decisions (the GUI moves machines; a big or hostile input must not stall its jogs):

* A request body is at most :data:`MAX_BODY_BYTES` (the largest legitimate one, a parameter
  backup being restored, is under a kilobyte). A larger ``Content-Length`` is answered 413
  before any of the body is read; a body streamed without one (chunked) is counted as it
  arrives and answered 413 as soon as it passes the limit. What is under the limit is read
  by :class:`BodyLimit` and handed to the app in one piece.
* A WebSocket message is at most :data:`MAX_MESSAGE_BYTES` (the page's largest is a scope
  configuration of a few hundred bytes); a larger one closes the socket with code 1009
  ("message too big", RFC 6455). uvicorn enforces it on the wire (:data:`UVICORN_LIMITS`),
  the app checks it again.
* JSON is read by :func:`servobus.bounded_json.loads` (shared with the gateway): nested
  deeper than 32 levels, numbers beyond a double's range, ``NaN``/``Infinity`` and text
  that is not JSON are refused (400, or an ``error`` message on the WebSocket) before
  anything uses them; the nesting is checked before the text is parsed, so a maximal input
  costs the loop a few milliseconds (``benchmarks/bench_gui.py`` prints the stall).
"""

from __future__ import annotations

import json

from servobus.gui.auth import ASGIApp, Message, Receive, Scope, Send

MAX_BODY_BYTES = 64 * 1024
MAX_MESSAGE_BYTES = 16 * 1024
CLOSE_TOO_BIG = 1009
#: uvicorn's own limits (servobus.gui.server): WebSocket frames, HTTP header block.
UVICORN_LIMITS: dict[str, int] = {"ws_max_size": MAX_MESSAGE_BYTES,
                                  "h11_max_incomplete_event_size": 64 * 1024}


class BodyLimit:
    """ASGI middleware: request bodies of at most ``limit`` bytes, else 413 (see above)."""

    def __init__(self, app: ASGIApp, limit: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = _content_length(scope)
        if declared is not None and declared > self.limit:
            await self._refuse(send, f"the request body ({declared} bytes) is larger than "
                                     f"{self.limit} bytes")
            return
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away
                return
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.limit:
                await self._refuse(send, f"the request body is larger than {self.limit} bytes")
                return
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, when it comes

        await self.app(scope, replay, send)

    @staticmethod
    async def _refuse(send: Send, text: str) -> None:
        body = json.dumps({"error": text, "kind": "PayloadTooLarge"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"),
                                (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


def _content_length(scope: Scope) -> int | None:
    for key, value in scope["headers"]:
        if key.lower() == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None  # the server refuses a malformed length itself
    return None
