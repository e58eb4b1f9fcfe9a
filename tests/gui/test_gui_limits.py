"""Bounded inputs of the GUI server (issue 17.3): bodies, WebSocket messages, JSON nesting.

The sizes and codes on the real server (uvicorn on a thread, served as ``servobus gui``
serves it: servobus.gui.server.uvicorn_config) with raw sockets, so a body can be declared
and never sent, or streamed; the answers to bad messages in-process (Starlette TestClient).
"""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
import uvicorn
from rig import wait_until
from starlette.testclient import TestClient
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect as ws_connect

from servobus.bounded_json import MAX_DEPTH
from servobus.gui.app import create_app
from servobus.gui.limits import CLOSE_TOO_BIG, MAX_BODY_BYTES, MAX_MESSAGE_BYTES
from servobus.gui.server import bind, uvicorn_config

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"


@pytest.fixture(scope="module")
def server() -> Iterator[int]:
    """The GUI (three virtual drives) on a free port; its port."""
    sock = bind("127.0.0.1", 0)
    srv = uvicorn.Server(uvicorn_config(create_app()))
    thread = threading.Thread(target=lambda: asyncio.run(srv.serve(sockets=[sock])),
                              daemon=True)
    thread.start()
    wait_until(lambda: srv.started, timeout=20, what="the GUI server started")
    try:
        yield sock.getsockname()[1]
    finally:
        srv.should_exit = True
        thread.join(timeout=15)
        sock.close()


def raw(port: int) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=10)


def head(path: str, extra: str) -> bytes:
    return (f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            f"{extra}\r\n").encode()


def answer(sock: socket.socket) -> tuple[int, dict[str, Any]]:
    """Status and JSON body of one HTTP answer (read until the server closes or it is all)."""
    data = b""
    while b"\r\n\r\n" not in data or len(data.split(b"\r\n\r\n", 1)[1]) < _length(data):
        chunk = sock.recv(65536)
        if not chunk:
            break
        data += chunk
    header, body = data.split(b"\r\n\r\n", 1)
    return int(header.split()[1]), json.loads(body)


def _length(data: bytes) -> int:
    for line in data.split(b"\r\n\r\n", 1)[0].split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            return int(value)
    return 1 << 30


def get(port: int, path: str) -> int:
    with raw(port) as s:
        s.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
        return answer(s)[0]


# ------------------------------------------------------------------ HTTP bodies
def test_a_declared_big_body_is_refused_before_it_is_sent(server: int) -> None:
    with raw(server) as s:
        s.sendall(head("/api/axes/1/move", "Content-Length: 50000000\r\n") + b"{" * 1000)
        status, doc = answer(s)  # the other 49.99 MB are never sent
    assert status == 413 and f"larger than {MAX_BODY_BYTES} bytes" in doc["error"]


def test_a_streamed_body_is_cut_off_at_the_limit(server: int) -> None:
    """413 once the limit is passed, and the connection is closed: the rest of a 50 MB body
    is not read (what the client gets out is at most the limit plus the sockets' buffers)."""
    chunk = b" " * 8192
    frame = b"%x\r\n%s\r\n" % (len(chunk), chunk)
    sent = 0
    status = 0
    with raw(server) as s:
        s.sendall(head("/api/axes/1/move", "Transfer-Encoding: chunked\r\n"))
        s.settimeout(5)
        try:
            while sent < 50_000_000:
                s.sendall(frame)
                sent += len(frame)
                if not status and _readable(s):
                    status, doc = answer(s)
        except OSError:  # reset or broken pipe: the server closed the connection
            pass
        if not status:
            status, doc = answer(s)
    assert status == 413 and "larger than" in doc["error"]
    assert sent < 25_000_000  # the server stopped reading long before the end


def _readable(s: socket.socket) -> bool:
    import select

    return bool(select.select([s], [], [], 0)[0])


def test_a_small_request_is_served_while_a_big_one_is_refused(server: int) -> None:
    outcome: list[int] = []
    started = threading.Event()

    def upload() -> None:  # a big body, streamed slowly
        with raw(server) as s:
            s.sendall(head("/api/axes/1/move", "Transfer-Encoding: chunked\r\n"))
            started.set()
            try:
                for _ in range(4 * MAX_BODY_BYTES // 1024):
                    s.sendall(b"400\r\n" + b" " * 1024 + b"\r\n")
                    time.sleep(0.001)  # a slow sender: the server waits for its bytes
            except (BrokenPipeError, ConnectionResetError):
                pass
            outcome.append(answer(s)[0])

    thread = threading.Thread(target=upload)
    thread.start()
    started.wait(10)
    assert get(server, "/api/axes") == 200  # while the upload is under way
    thread.join(20)
    assert outcome == [413]


def test_a_body_within_the_limit_is_served(server: int) -> None:
    body = json.dumps({"action": "stop", "pad": " " * (MAX_BODY_BYTES - 100)}).encode()
    with raw(server) as s:
        s.sendall(head("/api/axes/1/command", f"Content-Length: {len(body)}\r\n") + body)
        assert answer(s)[0] == 200


# ------------------------------------------------------------------ JSON nesting
@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with TestClient(create_app(), base_url=BASE) as c:
        yield c


@pytest.mark.parametrize("body,text", [
    ("[" * 50_000, f"nested deeper than {MAX_DEPTH} levels"),
    ("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), f"nested deeper than {MAX_DEPTH} levels"),
    ('{"value": ' + "[" * 5000 + "]" * 5000 + "}", "nested deeper"),
    ("{nope", "not JSON"),
    (json.dumps([1, 2]), "must be a JSON object"),
    ('{"value": 1e400}', "beyond a double's range"),
    ('{"value": ' + "9" * 400 + "}", "beyond a double's range"),
    ('{"value": -1e999}', "beyond a double's range"),
    ('{"value": NaN}', "NaN is not a JSON number"),
], ids=["50000-deep", "just-too-deep", "5000-deep-value", "not-json", "not-an-object",
        "1e400", "400-digits", "-1e999", "NaN"])
def test_deep_or_bad_json_is_400_naming_the_problem(client: TestClient, body: str,
                                                     text: str) -> None:
    r = client.post("/api/axes/1/move", content=body,
                    headers={"Content-Type": "application/json"})
    assert r.status_code == 400 and text in r.json()["error"]


def test_json_within_the_nesting_limit_is_served(client: TestClient) -> None:
    deep = json.dumps({"value": 0, "x": json.loads("[" * 20 + "]" * 20)})
    r = client.post("/api/axes/3/move", content=deep,
                    headers={"Content-Type": "application/json"})
    assert r.status_code == 200, r.text


# ------------------------------------------------------------------ WebSocket
def next_error(ws: Any) -> dict[str, Any]:
    while True:
        doc: dict[str, Any] = json.loads(ws.receive_text())
        if doc["type"] == "error":
            return doc


def test_every_bad_message_is_answered_naming_it_and_the_session_goes_on(
        client: TestClient) -> None:
    with client.websocket_connect(WS) as ws:
        ws.send_text("this is not json")  # the first message
        first = next_error(ws)
        assert first["request"] == "" and first["received"] == "this is not json"
        assert "not JSON" in first["message"]
        ws.send_text(json.dumps({"type": "jog", "axis": "x", "rpm": 10}))
        assert next_error(ws)["request"] == "jog"
        ws.send_text("[" * 10_000)  # names this message, not the jog before it
        deep = next_error(ws)
        assert deep["request"] == "" and "nested deeper" in deep["message"]
        assert deep["received"].startswith("[[[[") and len(deep["received"]) < 50
        ws.send_text('{"type": "jog", "axis": 1, "rpm": ' + "9" * 400 + "}")
        huge = next_error(ws)
        assert huge["request"] == "" and "beyond a double's range" in huge["message"]
        ws.send_bytes(b"\x00\x01")
        assert "binary" in next_error(ws)["message"]
        ws.send_text(json.dumps({"type": "stop_all"}))  # the session is still there
        while (doc := json.loads(ws.receive_text()))["type"] != "stopped":
            pass
        assert doc["failed"] == {}


def test_a_message_over_the_limit_closes_with_1009_in_process(client: TestClient) -> None:
    with client.websocket_connect(WS) as ws:
        ws.send_text(json.dumps({"type": "ack", "pad": "x" * MAX_MESSAGE_BYTES}))
        while True:
            message = ws.receive()
            if message["type"] == "websocket.close":
                break
    assert message["code"] == CLOSE_TOO_BIG


def test_a_message_over_the_limit_closes_with_1009_on_the_wire(server: int) -> None:
    with ws_connect(f"ws://127.0.0.1:{server}/ws", max_size=None) as ws:
        ws.send(json.dumps({"type": "ack", "seq": 1}))
        ws.send("x" * (MAX_MESSAGE_BYTES + 1))
        with pytest.raises(ConnectionClosed) as closed:
            for _ in range(10_000):
                ws.recv(timeout=10)
    assert closed.value.rcvd is not None and closed.value.rcvd.code == CLOSE_TOO_BIG
