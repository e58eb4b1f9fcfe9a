"""Fair limits per page and error boundaries of the GUI server (issue 30): requests in
flight per page and in all (Stop always served), pages at once, scope channels per page,
and an unexpected error in one request or message failing that one only. In-process
(Starlette TestClient); a request is held in flight by an axis call that waits on a gate."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import pytest
from rig import wait_until
from starlette.testclient import TestClient, WebSocketTestSession

from servobus.gui import fair
from servobus.gui.app import create_app
from servobus.gui.boundary import ErrorBoundary
from servobus.gui.scope_session import MAX_CHANNELS
from servobus.gui.state import GuiState

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"
ENABLE = {"action": "enable"}


@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with TestClient(create_app(), base_url=BASE) as c:
        yield c


def gui_of(client: TestClient) -> GuiState:
    state: GuiState = client.app.state.gui  # type: ignore[attr-defined]
    return state


class Gate:
    """An axis call that waits until :meth:`open` (from the test's thread)."""

    def __init__(self) -> None:
        self.entered = 0
        self.pool = ThreadPoolExecutor(max_workers=fair.MAX_REQUESTS_PER_CLIENT + 2)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._event: asyncio.Event | None = None

    async def wait(self) -> None:
        if self._event is None:
            self._loop, self._event = asyncio.get_running_loop(), asyncio.Event()
        self.entered += 1
        await self._event.wait()

    def open(self) -> None:
        if self._loop is not None and self._event is not None:
            self._loop.call_soon_threadsafe(self._event.set)


@pytest.fixture
def gate(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> Iterator[Gate]:
    """Enabling axis 1 waits on the gate (a request in flight for as long as the test likes);
    opened at the end whatever happened."""
    g = Gate()
    monkeypatch.setattr(gui_of(client).fleet.get(1).axis, "enable", g.wait)
    try:
        yield g
    finally:
        g.open()  # first: the pool's threads wait for their answers
        g.pool.shutdown(wait=True)


def hello(ws: WebSocketTestSession) -> int:
    while True:
        doc = json.loads(ws.receive_text())
        if doc["type"] == "hello":
            return int(doc["owner"])


def post(client: TestClient, path: str, doc: dict[str, object], page: int | None = None
         ) -> tuple[int, dict[str, Any]]:
    headers = {"Content-Type": "application/json"}
    if page is not None:
        headers["X-Servobus-Page"] = str(page)
    r = client.post(path, content=json.dumps(doc), headers=headers)
    return r.status_code, r.json()


def hold(client: TestClient, gate: Gate, count: int, page: int | None
         ) -> list[Future[tuple[int, dict[str, Any]]]]:
    """``count`` more enables of axis 1 in flight, each waiting on the gate."""
    before = gate.entered
    held = [gate.pool.submit(post, client, "/api/axes/1/command", ENABLE, page)
            for _ in range(count)]
    wait_until(lambda: gate.entered == before + count, timeout=20,
               what=f"{count} requests in flight")
    return held


# ------------------------------------------------------------------ requests in flight
def test_a_page_has_at_most_8_requests_in_flight_stop_is_always_served(
        client: TestClient, gate: Gate, caplog: pytest.LogCaptureFixture) -> None:
    with client.websocket_connect(WS) as ws_a, client.websocket_connect(WS) as ws_b, \
            caplog.at_level(logging.WARNING, logger="servobus.gui.fair"):
        page_a, page_b = hello(ws_a), hello(ws_b)
        held = hold(client, gate, fair.MAX_REQUESTS_PER_CLIENT, page_a)
        for _ in range(3):
            status, doc = post(client, "/api/axes/2/command", ENABLE, page_a)
            assert status == 429 and doc["kind"] == "TooManyRequests"
            assert "this page has 8 requests in progress" in doc["error"]
        # Stop is never refused, the page's other requests hang as they may
        assert post(client, "/api/axes/2/command", {"action": "stop"}, page_a)[0] == 200
        assert post(client, "/api/stop_all", {}, page_a)[0] == 200
        # another page, and a client without a page (its peer address), are served
        assert post(client, "/api/axes/2/command", ENABLE, page_b)[0] == 200
        assert post(client, "/api/axes/2/command", ENABLE)[0] == 200
        # a page number that is not connected counts for the peer address, not that page
        assert post(client, "/api/axes/2/command", ENABLE, page_b + 1000)[0] == 200
        refusals = [r for r in caplog.records if "refusing more (429)" in r.getMessage()]
        assert len(refusals) == 1 and f"page {page_a}" in refusals[0].getMessage()
        gate.open()
        assert [f.result(timeout=20)[0] for f in held] == [200] * len(held)
        assert post(client, "/api/axes/2/command", ENABLE, page_a)[0] == 200  # room again


def test_the_page_files_load_while_their_peer_has_8_requests_in_flight(
        client: TestClient, gate: Gate) -> None:
    # a browser fetches the page's dozen modules at once, before its WebSocket names the
    # page: counted per peer, one was refused (429) and the page never started
    held = hold(client, gate, fair.MAX_REQUESTS_PER_CLIENT, None)
    assert post(client, "/api/axes/2/command", ENABLE)[0] == 429  # the peer is full ...
    for path in ("/", "/static/js/app.js", "/static/js/gate.js", "/static/style.css"):
        assert client.get(path).status_code == 200, path  # ... its page still loads
    gate.open()
    assert [f.result(timeout=20)[0] for f in held] == [200] * len(held)


def test_all_clients_together_are_held_to_the_cap_in_all(
        client: TestClient, gate: Gate, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fair, "MAX_REQUESTS", 10)  # the rule, with fewer threads than 64
    with client.websocket_connect(WS) as ws_a, client.websocket_connect(WS) as ws_b:
        page_a, page_b = hello(ws_a), hello(ws_b)
        held = hold(client, gate, 8, page_a) + hold(client, gate, 2, None)
        status, doc = post(client, "/api/axes/2/command", ENABLE, page_b)
        assert status == 503 and doc["kind"] == "ServerBusy" and "try again" in doc["error"]
        assert post(client, "/api/stop_all", {}, page_b)[0] == 200
        gate.open()
        assert [f.result(timeout=20)[0] for f in held] == [200] * 10
        assert post(client, "/api/axes/2/command", ENABLE, page_b)[0] == 200


# ------------------------------------------------------------------ pages and channels
def test_one_page_more_than_the_cap_is_told_why_and_closed_with_1013(
        client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fair, "MAX_PAGES", len(gui_of(client).sessions) + 2)
    with client.websocket_connect(WS) as first, client.websocket_connect(WS) as second:
        hello(first), hello(second)
        with client.websocket_connect(WS) as third:
            doc = json.loads(third.receive_text())
            assert doc["type"] == "error" and "at most" in doc["message"]
            closed = third.receive()
            assert closed["type"] == "websocket.close"
            assert closed["code"] == fair.CLOSE_TRY_AGAIN_LATER
    with client.websocket_connect(WS) as again:  # the others closed: room again
        assert hello(again) > 0


def next_error(ws: WebSocketTestSession) -> dict[str, Any]:
    while True:
        doc: dict[str, Any] = json.loads(ws.receive_text())
        if doc["type"] == "error":
            return doc


def test_a_page_scope_shows_at_most_8_channels_however_often_it_is_set(
        client: TestClient) -> None:
    sampler = gui_of(client).samplers[1]
    before = len(sampler._wanted)
    channel = {"axis": 1, "signal": "position"}
    with client.websocket_connect(WS) as ws:
        hello(ws)
        too_many = {"channels": [channel] * (MAX_CHANNELS + 1), "mode": "roll"}
        ws.send_text(json.dumps({"type": "scope", "settings": too_many}))
        error = next_error(ws)
        assert error["request"] == "scope"
        assert f"a page's scope shows 1 to {MAX_CHANNELS} channels, got 9" in error["message"]
        assert len(sampler._wanted) == before  # nothing subscribed
        for _ in range(5):
            ws.send_text(json.dumps({"type": "scope", "settings": {
                "channels": [channel] * MAX_CHANNELS, "mode": "roll"}}))
        ws.send_text(json.dumps({"type": "scope_csv"}))  # answered after the 5 configurations
        while True:  # the scope's binary frames may come first: skip them
            message = ws.receive()
            if "text" in message and json.loads(message["text"])["type"] in ("csv", "error"):
                break
        assert len(sampler._wanted) == before + 1  # one subscription for this page
    wait_until(lambda: len(sampler._wanted) == before, what="the page's subscription ended")


# ------------------------------------------------------------------ error boundaries
def test_an_unexpected_error_in_a_request_is_a_500_and_one_log_line(
        client: TestClient, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    async def broken() -> None:
        raise ZeroDivisionError("a bug in the handler")

    monkeypatch.setattr(gui_of(client).fleet.get(1).axis, "enable", broken)
    with caplog.at_level(logging.DEBUG, logger="servobus.gui"):
        status, doc = post(client, "/api/axes/1/command", ENABLE)
    assert status == 500 and doc["kind"] == "InternalError"
    assert "ZeroDivisionError: a bug in the handler" in doc["error"]
    lines = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(lines) == 1
    assert lines[0].getMessage() == ("GUI POST /api/axes/1/command failed: "
                                     "ZeroDivisionError: a bug in the handler")
    assert client.get("/api/axes").status_code == 200  # the server goes on
    assert post(client, "/api/axes/2/command", ENABLE)[0] == 200


def test_an_unexpected_error_in_a_message_is_an_error_message_and_the_page_goes_on(
        client: TestClient, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    async def broken(*args: object, **kwargs: object) -> None:
        raise KeyError("a bug in the jog")

    monkeypatch.setattr(gui_of(client).jog, "jog", broken)
    with client.websocket_connect(WS) as ws, \
            caplog.at_level(logging.WARNING, logger="servobus.gui"):
        owner = hello(ws)
        ws.send_text(json.dumps({"type": "jog", "axis": 1, "rpm": 10}))
        error = next_error(ws)
        assert error["request"] == "jog" and "internal error (KeyError)" in error["message"]
        ws.send_text(json.dumps({"type": "stop_all"}))  # the page is still connected
        while (doc := json.loads(ws.receive_text()))["type"] != "stopped":
            pass
        assert doc["failed"] == {}
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert lines == [f"GUI WebSocket message 'jog' of page {owner} failed: KeyError: "
                     "'a bug in the jog'"]


async def test_the_boundary_answers_what_it_can_and_never_raises() -> None:
    """Raw ASGI: before the answer a 500; after it started nothing more (the connection is
    cut); a WebSocket is closed with 1011."""

    def failing(after_start: bool) -> Any:
        async def app(scope: Any, receive: Any, send: Any) -> None:
            if after_start:
                await send({"type": "http.response.start", "status": 200, "headers": []})
            raise RuntimeError("boom")
        return app

    async def run(app: Any, kind: str) -> list[dict[str, Any]]:
        sent: list[dict[str, Any]] = []

        async def send(message: Any) -> None:
            sent.append(message)

        async def receive() -> Any:
            return {"type": "http.disconnect"}

        scope = {"type": kind, "method": "GET", "path": "/x", "headers": []}
        await ErrorBoundary(app)(scope, receive, send)
        return sent

    before = await run(failing(False), "http")
    assert before[0]["status"] == 500 and b"RuntimeError: boom" in before[1]["body"]
    after = await run(failing(True), "http")
    assert [m["type"] for m in after] == ["http.response.start"]
    ws = await run(failing(False), "websocket")
    assert ws == [{"type": "websocket.close", "code": 1011, "reason": "internal error"}]
