"""Who may command the drives through the GUI (an ASGI middleware in front of the app).

Decisions (the GUI moves real machines):

* A token, when set, is required on every request and WebSocket: in the ``token`` query
  parameter (the URL the command prints), the ``X-Servobus-Token`` header (the page's
  fetches) or the ``servobus_token`` cookie (set, HttpOnly and SameSite=Strict, when the
  page is opened with a valid token, so its scripts and styles load).
* Without a token (loopback only, the command refuses otherwise) the Host header must be a
  loopback name: another web site reached through a DNS-rebound name is refused.
* Commands (POST) must be JSON and a WebSocket must come from the page's own origin: a
  foreign page in the same browser can neither submit a form that moves an axis nor open
  the WebSocket (browsers send JSON cross-site only after a CORS preflight, which is never
  granted).
"""

from __future__ import annotations

import hmac
import json
from collections.abc import Awaitable, Callable, MutableMapping
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qs, urlsplit

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

COOKIE = "servobus_token"
HEADER = "x-servobus-token"
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]", "::1")


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


def host_name(host_header: str) -> str:
    if host_header.startswith("["):
        return host_header.split("]", 1)[0] + "]"
    return host_header.rsplit(":", 1)[0] if host_header.count(":") == 1 else host_header


class Guard:
    def __init__(self, app: ASGIApp, token: str | None) -> None:
        self.app = app
        self.token = token or None

    def _token_given(self, scope: Scope, headers: dict[str, str]) -> tuple[str | None, bool]:
        """(token found, found in the query string)."""
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        if "token" in query:
            return query["token"][-1], True
        if HEADER in headers:
            return headers[HEADER], False
        cookie = SimpleCookie(headers.get("cookie", ""))
        if COOKIE in cookie:
            return cookie[COOKIE].value, False
        return None, False

    def refusal(self, scope: Scope) -> tuple[int, str] | None:
        headers = _headers(scope)
        if self.token is not None:
            given, _ = self._token_given(scope, headers)
            if given is None or not hmac.compare_digest(given.encode(), self.token.encode()):
                return 401, "a valid token is needed (open the URL servobus gui printed)"
        elif host_name(headers.get("host", "")) not in LOOPBACK_NAMES:
            return 403, "this GUI answers on its loopback address only"
        if scope["type"] == "websocket":
            origin = headers.get("origin")
            if origin and urlsplit(origin).netloc != headers.get("host"):
                return 403, "WebSocket from a foreign origin"
        elif scope["method"] not in ("GET", "HEAD", "OPTIONS"):
            ctype = headers.get("content-type", "").split(";")[0].strip().lower()
            if ctype != "application/json":
                return 415, "commands are JSON (Content-Type: application/json)"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        refused = self.refusal(scope)
        if refused is not None:
            status, text = refused
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 4000 + status % 1000,
                            "reason": text})
                return
            body = json.dumps({"error": text}).encode()
            await send({"type": "http.response.start", "status": status,
                        "headers": [(b"content-type", b"application/json"),
                                    (b"content-length", str(len(body)).encode())]})
            await send({"type": "http.response.body", "body": body})
            return
        given, in_query = self._token_given(scope, _headers(scope))
        if self.token is None or not in_query or scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_cookie(message: Message) -> None:
            if message["type"] == "http.response.start":
                cookie = f"{COOKIE}={given}; Path=/; HttpOnly; SameSite=Strict"
                message["headers"] = [*message.get("headers", []),
                                      (b"set-cookie", cookie.encode("latin-1"))]
            await send(message)

        await self.app(scope, receive, send_with_cookie)
