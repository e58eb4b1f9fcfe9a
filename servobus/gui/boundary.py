"""Every HTTP request and WebSocket of the GUI in its own error boundary (ASGI middleware).

Decision (issue 30): an unexpected error in one request - a bug, an exception no handler
maps to a status (servobus.gui.errors) - must not take more than that request. It becomes
a 500 answer ``{"error": "internal error (...)", "kind": "InternalError"}`` and one log
line naming the request and the error (its traceback only at DEBUG level); a WebSocket whose
handler fails is closed with 1011 ("internal error", RFC 6455). The server goes on serving.
Each WebSocket message has its own boundary as well (servobus.gui.ws): a message that fails
is answered with an ``error`` message and the page stays connected.

The boundary is the outermost middleware (servobus.gui.app), so it also covers the Guard,
the body limit and the fair limits.
"""

from __future__ import annotations

import contextlib
import json
import logging

from servobus.bounded_json import excerpt
from servobus.gui.auth import ASGIApp, Message, Receive, Scope, Send

log = logging.getLogger(__name__)
CLOSE_INTERNAL_ERROR = 1011


class ErrorBoundary:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        answered = False

        async def watched(message: Message) -> None:
            nonlocal answered
            if message["type"] == "http.response.start":
                answered = True
            await send(message)

        try:
            await self.app(scope, receive, watched)
        except Exception as exc:  # the boundary: one request fails, the server goes on
            what = f"{scope.get('method', 'WebSocket')} {scope.get('path', '')}"
            log.error("GUI %s failed: %s: %s", what, type(exc).__name__, excerpt(str(exc), 300))
            log.debug("GUI %s failed", what, exc_info=True)
            with contextlib.suppress(Exception):  # the client may be gone already
                if scope["type"] == "websocket":
                    await send({"type": "websocket.close", "code": CLOSE_INTERNAL_ERROR,
                                "reason": "internal error"})
                elif not answered:
                    await _internal_error(send, exc)


async def _internal_error(send: Send, exc: Exception) -> None:
    text = f"internal error ({type(exc).__name__}: {excerpt(str(exc), 200)}); the server goes on"
    body = json.dumps({"error": text, "kind": "InternalError"}).encode()
    await send({"type": "http.response.start", "status": 500,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})
