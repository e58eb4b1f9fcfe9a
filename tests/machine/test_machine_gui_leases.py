"""The GUI's motion as leases of the machine axis (issue 27), in-process on a machine file
with soft limits: jogs at a limit move 0 counts, a step test and a wave that would pass a
limit are refused with no motion command on the wire, one page per axis, STOP ALL wins."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from machine_rig import write_machine
from rig import wait_until
from starlette.testclient import TestClient, WebSocketTestSession

from servobus.families.dmm.vocabulary import DmmFunction as F
from servobus.gui.app import create_app
from servobus.gui.state import GuiState
from servobus.transport.base import Direction

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"
REV = 65536

#: One DMM axis in rev with a short travel: the limits are reached in a fraction of a second.
LIMITED = """\
name = "lease-cell"

[axes.t]
url = "sim://dyn232?fast=1"
id = 1
unit = "rev"
limits = [-1.0, 1.0]
"""
#: What moves a DMM motor (DYN232M 7.2.4): none of these may follow a refusal.
MOTION = {F.GO_ABSOLUTE_POS, F.MAKE_LINEAR_LINE, F.GO_RELATIVE_POS, F.MAKE_CIRCULAR_ARC,
          F.TURN_CONST_SPEED, F.SQUARE_WAVE, F.SIN_WAVE, F.SS_FREQUENCY}


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    app = create_app(machine=write_machine(tmp_path, LIMITED))
    with TestClient(app, base_url=BASE) as c:
        wait_until(lambda: "user_position" in status(c), what="first status")
        yield c


def status(client: TestClient) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[0]["status"]
    return doc


def gui(client: TestClient) -> GuiState:
    state: GuiState = client.app.state.gui  # type: ignore[attr-defined]
    return state


def motion_sent(client: TestClient, after: int) -> list[object]:
    """Motion commands the GUI's trace hook saw sent since entry ``after``."""
    return [e.item for e in list(gui(client).fleet.traffic.entries)
            if e.seq > after and e.direction is Direction.TX
            and getattr(e.item, "function", None) in MOTION]


def last_seq(client: TestClient) -> int:
    entries = gui(client).fleet.traffic.entries
    return entries[-1].seq if entries else 0


class Page:
    def __init__(self, ws: WebSocketTestSession) -> None:
        self.ws = ws
        self.messages: list[dict[str, Any]] = []
        self.owner = self.until(lambda: self.last("hello"))["owner"]

    def send(self, doc: dict[str, object]) -> None:
        self.ws.send_text(json.dumps(doc))

    def until(self, predicate: Callable[[], Any], timeout: float = 15.0) -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            message = self.ws.receive()
            if message.get("text") is not None:
                self.messages.append(json.loads(message["text"]))
        pytest.fail("not seen in time")

    def last(self, kind: str) -> dict[str, Any] | None:
        return next((m for m in reversed(self.messages) if m["type"] == kind), None)

    def error_after(self, count: int) -> dict[str, Any]:
        return self.until(lambda: next((m for m in self.messages[count:]
                                        if m["type"] == "error"), None))  # type: ignore[no-any-return]


def settle_at(client: TestClient, rev: float, *, exact: bool = False) -> None:
    """Moved to ``rev`` and at rest; ``exact``: on its very count (``rev`` a whole count),
    not just in position: a servo in its in-position window (a few counts) still settles by
    a count or two, which a "0 counts moved" check would take for motion."""
    r = client.post("/api/axes/1/move", json={"value": rev, "unit": "rev"})
    assert r.status_code == 200, r.text

    def there() -> bool:
        now = status(client)
        near = (now["position"] == rev * REV if exact
                else abs(now["user_position"] - rev) < 1e-4)
        return near and not now["moving"]

    wait_until(there, timeout=30, what=f"t at {rev} rev")


def test_jogs_at_a_limit_move_zero_counts_and_the_page_is_told(client: TestClient) -> None:
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        # towards the limit: the lease's target stops there, the status says at_limit
        def at_limit() -> bool:
            status_doc = page.last("status") or {"leases": {}, "ended": {}}
            if status_doc["ended"].get("1"):  # a loaded machine let it lapse: press again
                page.send({"type": "jog_stop", "axis": 1})
            page.send({"type": "jog", "axis": 1, "rpm": 120})
            return bool(status_doc["leases"].get("1", {}).get("at_limit"))

        page.until(at_limit)
        page.send({"type": "jog_stop", "axis": 1})
        wait_until(lambda: not status(client)["moving"], timeout=10, what="at rest")
        # the target stood at the limit; the servo rests within its in-position window
        # (1/1024 rev on DMM, about 7e-5 rev measured) of it
        assert status(client)["user_position"] <= 1.0 + 1 / 1024
        settle_at(client, 1.0, exact=True)  # exactly at the limit
        before = status(client)["position"]
        mark = last_seq(client)
        for _ in range(5):  # every press further out: refused, nothing moves
            count = len(page.messages)
            page.send({"type": "jog", "axis": 1, "rpm": 120})
            error = page.error_after(count)
            assert error["request"] == "jog" and "at soft limit" in error["message"], error
            page.send({"type": "jog_stop", "axis": 1})
        assert motion_sent(client, mark) == []
        assert status(client)["position"] == before  # 0 counts
        assert client.get("/api/diagnostics").json()["jog"]["active"] == {}  # nothing lit


def test_step_test_and_wave_past_a_limit_are_refused_before_the_wire(
        client: TestClient) -> None:
    settle_at(client, 0.9)
    mark = last_seq(client)
    r = client.post("/api/axes/1/tuning/step", json={"distance": REV // 4, "duration_s": 0.5})
    assert r.status_code == 400 and r.json()["kind"] == "LimitError", r.text
    assert "soft limits" in r.json()["error"]
    # 4096 = 180 deg of swing each way from 0.9 rev: past +1 rev
    r = client.post("/api/axes/1/wave", json={"kind": "sine", "amplitude": 4096, "hz": 2})
    assert r.status_code == 400 and r.json()["kind"] == "LimitError", r.text
    assert motion_sent(client, mark) == [], "a refused step or wave sends no motion command"
    assert abs(status(client)["user_position"] - 0.9) < 1e-4
    # inside the limits both run (the wave stopped again by the host)
    r = client.post("/api/axes/1/wave", json={"kind": "sine", "amplitude": 100, "hz": 2})
    assert r.status_code == 200, r.text
    assert client.post("/api/axes/1/wave", json={"kind": "off"}).status_code == 200


def test_a_second_page_is_refused_naming_the_owner_and_stop_all_wins(
        client: TestClient) -> None:
    with client.websocket_connect(WS) as ws_a, client.websocket_connect(WS) as ws_b:
        a, b = Page(ws_a), Page(ws_b)
        a.send({"type": "jog", "axis": 1, "rpm": -60})
        a.until(lambda: (s := a.last("status")) and s["leases"].get("1", {}).get("mine"))
        count = len(b.messages)
        b.send({"type": "jog", "axis": 1, "rpm": 60})
        error = b.error_after(count)
        assert f"held by page {a.owner}" in error["message"], error
        r = client.post("/api/axes/1/turn", json={"rpm": 60, "page": b.owner})
        assert r.status_code == 409 and r.json()["kind"] == "OwnerError", r.text
        b.send({"type": "stop_all"})  # STOP ALL wins over the holder
        b.until(lambda: b.last("stopped"))
        count = len(a.messages)
        a.send({"type": "jog", "axis": 1, "rpm": -60})  # its renewal restarts nothing
        assert "ended" in a.error_after(count)["message"]
        a.until(lambda: (s := a.last("status")) and s["ended"].get("1") == "stopped")
        wait_until(lambda: not status(client)["moving"], timeout=10, what="stopped")
        assert client.get("/api/diagnostics").json()["jog"]["active"] == {}
