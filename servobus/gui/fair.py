"""Fair limits per page of the GUI server: pages, requests in flight, scope channels.

Decisions (issue 30: one page, or one script, must not take the server from the others):

* **Pages.** At most :data:`MAX_PAGES` WebSockets (pages) at once; one more is accepted,
  told why in an ``error`` message and closed with 1013 ("try again later", RFC 6455). Each
  page costs the loop a status every 0.1 s and its scope frames.
* **A page's WebSocket** handles one message at a time, in order (servobus.gui.ws): a page
  has at most one WebSocket request in flight, and what it sends meanwhile waits in the
  socket (bounded by the WebSocket library's queue and TCP's window).
* **A page's scope** shows at most :data:`servobus.gui.scope_session.MAX_CHANNELS`
  channels: one scope session per page, a new configuration replaces the old one and its
  sampler subscriptions.
* **HTTP requests in flight.** At most :data:`MAX_REQUESTS_PER_CLIENT` requests of one
  client in progress (429 beyond, with ``Retry-After``), :data:`MAX_REQUESTS` of all clients
  (503 beyond). A client is the page that sends the ``X-Servobus-Page`` header with its
  WebSocket's number (``hello``'s ``owner``; the page's fetches do, static/js/net.js) while
  that page is connected; any other request counts for its peer address (a script, curl,
  a page before its WebSocket is up). A page waits for most answers before the next
  request, so 8 in flight is far more than it uses; a request that waits on a slow or dead
  link holds its place until it ends.
* **The page's own files** (``/``, ``/static/...``) count towards the total only, not per
  client: they are read from disk and never wait on a link, and a browser loading the
  page fetches its dozen modules at once, before its WebSocket can name the page - counted
  per peer they were refused (429) and the page did not start.
* **Stop is never refused** (docs/safety.md: Stop and STOP ALL always win):
  ``POST /api/stop_all`` and a ``command`` whose action is ``stop`` pass both caps and are
  not counted, even when the page's other requests hang on a dead link.
* One warning line when a client starts being refused, and one when the server is full
  (not one per refused request).
"""

from __future__ import annotations

import json
import logging
import re

from servobus import bounded_json
from servobus.errors import JsonRefused
from servobus.gui.auth import ASGIApp, Message, Receive, Scope, Send

log = logging.getLogger(__name__)

MAX_PAGES = 32
MAX_REQUESTS_PER_CLIENT = 8
MAX_REQUESTS = 64
CLOSE_TRY_AGAIN_LATER = 1013
PAGE_HEADER = b"x-servobus-page"
_COMMAND = re.compile(r"/api/axes/[^/]+/command")


def client_of(scope: Scope) -> str:
    """``page N`` when the request names a connected page, else ``peer <address>``."""
    for key, value in scope["headers"]:
        if key.lower() == PAGE_HEADER and value.isdigit() and len(value) <= 9:
            gui = getattr(scope["app"].state, "gui", None) if "app" in scope else None
            if gui is not None and int(value) in gui.jog.pages:
                return f"page {int(value)}"
    peer = scope.get("client")
    return f"peer {peer[0]}" if peer else "peer unknown"


class RequestCaps:
    """ASGI middleware: HTTP requests in flight per client and in all (see above). It sits
    after servobus.gui.limits.BodyLimit, which hands the body over in one piece."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.in_flight: dict[str, int] = {}  # only clients with requests in progress
        self.total = 0
        self._refusing: set[str] = set()  # clients whose refusal was logged
        self._full = False  # "the server is full" was logged

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        app = self.app
        if scope["type"] != "http":
            await app(scope, receive, send)
            return
        receive, stop = await _is_stop(scope, receive)
        if stop:
            await app(scope, receive, send)
            return
        client = "" if _page_file(scope["path"]) else client_of(scope)  # "": not counted
        count = self.in_flight.get(client, 0)
        if client and count >= MAX_REQUESTS_PER_CLIENT:
            self._log_once(client, f"GUI: {client} has {count} requests in progress: "
                                   "refusing more (429) until they end")
            what = "this page has" if client.startswith("page") else f"{client} has"
            await _refuse(send, 429, "TooManyRequests",
                          f"{what} {count} requests in progress (at most "
                          f"{MAX_REQUESTS_PER_CLIENT}): wait for their answers; Stop is "
                          "always served")
            return
        if self.total >= MAX_REQUESTS:
            if not self._full:
                self._full = True
                log.warning("GUI: %d requests in progress: refusing more (503) until fewer",
                            self.total)
            await _refuse(send, 503, "ServerBusy",
                          f"the GUI server has {self.total} requests in progress (at most "
                          f"{MAX_REQUESTS}): try again; Stop is always served")
            return
        if client:
            self.in_flight[client] = count + 1
        self.total += 1
        try:
            await app(scope, receive, send)
        finally:
            self.total -= 1
            if client:
                self._ended(client)
            if self._full and self.total <= MAX_REQUESTS // 2:
                self._full = False

    def _ended(self, client: str) -> None:
        left = self.in_flight[client] - 1
        if left:
            self.in_flight[client] = left
        else:
            del self.in_flight[client]
            self._refusing.discard(client)

    def _log_once(self, client: str, line: str) -> None:
        if client not in self._refusing:
            self._refusing.add(client)
            log.warning("%s", line)


def _page_file(path: str) -> bool:
    return path == "/" or path.startswith("/static/")


async def _is_stop(scope: Scope, receive: Receive) -> tuple[Receive, bool]:
    """Whether the request is a Stop; the body read to tell is handed on unchanged."""
    if scope["method"] != "POST":
        return receive, False
    if scope["path"] == "/api/stop_all":
        return receive, True
    if not _COMMAND.fullmatch(scope["path"]):
        return receive, False
    first = await receive()
    try:
        doc = bounded_json.loads(first.get("body", b"")) \
            if first["type"] == "http.request" and not first.get("more_body") else None
    except JsonRefused:
        doc = None  # the handler answers it
    replayed = False

    async def replay() -> Message:
        nonlocal replayed
        if not replayed:
            replayed = True
            return first
        return await receive()

    return replay, isinstance(doc, dict) and doc.get("action") == "stop"


async def _refuse(send: Send, status: int, kind: str, text: str) -> None:
    body = json.dumps({"error": text, "kind": kind}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()),
                            (b"retry-after", b"1")]})
    await send({"type": "http.response.body", "body": body})
