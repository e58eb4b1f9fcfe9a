"""The GUI in the axis's own units and names (issue 33), in-process (no browser).

A machine file's mm axis on a virtual DYN232M drive (tests/machine/machine_rig.MIXED, axis
x: 5 mm per revolution, limits -10..300, speed 50 mm/s): the server converts every number
the page types or is shown - jog and constant speed in mm/s, scope channels and the trigger
level in mm, step size and wave amplitude in mm - and names the axis in its messages.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from machine.machine_rig import write_machine
from rig import wait_until
from starlette.testclient import TestClient, WebSocketTestSession

from servobus.gui import frames
from servobus.gui.app import create_app

pytestmark = pytest.mark.timeout(90)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"
X = 1  # axis x: the first of the file


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    path = write_machine(tmp_path_factory.mktemp("units"))
    with TestClient(create_app(machine=path, jog_lease_s=1.0), base_url=BASE) as c:
        yield c


class Page:
    """A page on the WebSocket: its JSON messages and its (acked) scope frames."""

    def __init__(self, ws: WebSocketTestSession) -> None:
        self.ws = ws
        self.frames: list[frames.ScopeFrame] = []
        self.messages: list[dict[str, Any]] = []

    def send(self, doc: dict[str, object]) -> None:
        self.ws.send_text(json.dumps(doc))

    def until(self, predicate: Callable[[], Any], what: str, timeout: float = 30.0) -> Any:
        deadline = time.monotonic() + timeout
        while (value := predicate()) is None or value is False:
            assert time.monotonic() < deadline, f"not seen within {timeout} s: {what}"
            message = self.ws.receive()
            if message.get("bytes") is not None:
                frame = frames.decode(message["bytes"])
                self.frames.append(frame)
                self.send({"type": "ack", "seq": frame.seq})
            elif message.get("text") is not None:
                self.messages.append(json.loads(message["text"]))
        return value

    def last(self, kind: str) -> dict[str, Any] | None:
        return next((m for m in reversed(self.messages) if m["type"] == kind), None)


def post(client: TestClient, path: str, doc: object, code: int = 200) -> dict[str, Any]:
    r = client.post(path, json=doc)
    assert r.status_code == code, r.text
    result: dict[str, Any] = r.json()
    return result


def user_position(client: TestClient, axis: int = X) -> float:
    return float(client.get("/api/axes").json()[axis - 1]["status"]["user_position"])


def move_to(client: TestClient, mm: float) -> None:
    post(client, f"/api/axes/{X}/move", {"value": mm, "unit": "mm"})
    wait_until(lambda: abs(user_position(client) - mm) < 0.01, timeout=20,
               what=f"x at {mm} mm")


def test_identity_gives_the_units_the_page_shows(client: TestClient) -> None:
    axes = client.get("/api/info").json()["axes"]
    x, c = axes[0], axes[2]
    assert x["title"] == "axis x" and x["default_speed"] == 50.0
    units = x["units"]
    assert (units["position"], units["speed"]) == ("mm", "mm/s")
    assert units["signals"]["position"] == units["signals"]["position_error"] == "mm"
    assert units["signals"]["speed"] == "mm/s" and units["signals"]["current"] == "A"
    assert units["per_count"] == pytest.approx(1 / x["counts_per_unit"])
    assert units["per_rpm"] == pytest.approx(5.0 / 60)  # 5 mm per revolution
    assert (c["units"]["position"], c["units"]["speed"]) == ("deg", "deg/s")


def test_a_bare_url_is_shown_in_its_drive_family_units() -> None:
    with TestClient(create_app(), base_url=BASE) as bare:
        ident = bare.get("/api/info").json()["axes"][0]
    assert ident["title"] == "axis 1"
    assert (ident["units"]["position"], ident["units"]["speed"]) == ("counts", "rpm")
    assert ident["units"]["signals"]["position"] == "counts"


def test_jog_and_constant_speed_in_mm_per_s(client: TestClient) -> None:
    move_to(client, 0.0)
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        page.send({"type": "jog", "axis": X, "speed": 20.0})  # 20 mm/s = 240 rpm
        lease = page.until(lambda: (s := page.last("status")) and s["leases"].get(str(X)),
                           "the jog's lease")
        assert lease["speed"] == pytest.approx(20.0) and lease["speed_unit"] == "mm/s"
        assert lease["rpm"] == 240 and lease["mine"]
        page.send({"type": "jog_stop", "axis": X})
        # a speed past the drive's top (6000 rpm = 500 mm/s) is refused, naming the axis
        page.send({"type": "jog", "axis": X, "speed": 600.0})
        error = page.until(lambda: page.last("error"), "the refusal")
        assert "axis x" in error["message"] and "mm/s" in error["message"]
    doc = post(client, f"/api/axes/{X}/turn", {"speed": 10.0, "ttl": 0.3})
    assert (doc["speed"], doc["speed_unit"], doc["rpm"]) == (10.0, "mm/s", 120)
    post(client, f"/api/axes/{X}/command", {"action": "stop"})


def test_a_trigger_typed_as_75_mm_fires_at_75_mm(client: TestClient) -> None:
    move_to(client, 0.0)
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        page.send({"type": "scope", "settings": {
            "channels": [{"axis": X, "signal": "position"}, {"axis": X, "signal": "speed"}],
            "window_s": 1.0, "mode": "single", "edge": "rising", "level": 75.0, "pre": 0.5,
            "width": 400}})
        page.until(lambda: (s := page.last("scope_state")) and s["waiting"], "armed")
        post(client, f"/api/axes/{X}/move", {"value": 100.0, "unit": "mm"})
        frame = page.until(lambda: next((f for f in page.frames
                                         if f.flags & frames.FLAG_TRIGGERED), None),
                           "the triggered capture")
        position = [v for v in frame.ys[0] if math.isfinite(v)]
        # in mm: from 0 mm up (never past the move's 100 mm), the trigger at 75 mm
        assert min(position) > -1.0 and 75.0 < max(position) <= 100.5
        at_zero = min(range(len(frame.x)), key=lambda i: abs(frame.x[i]))
        assert frame.ys[0][at_zero] == pytest.approx(75.0, abs=3.0)
        speeds = [v for v in frame.ys[1] if math.isfinite(v)]
        assert 5.0 < max(speeds) < 500.0  # mm/s, not rpm (the move runs at hundreds of rpm)
        page.send({"type": "scope_csv"})
        csv = page.until(lambda: page.last("csv"), "the CSV")["text"]
        assert csv.splitlines()[0] == "x.t_s,x.position_mm,x.speed_mm_per_s"
    wait_until(lambda: abs(user_position(client) - 100.0) < 0.01, timeout=20, what="at 100")


def test_a_rising_trigger_in_mm_on_a_reversed_axis(client: TestClient) -> None:
    """Axis y has ``direction = -1``: its counts fall while its mm rise, and a rising
    trigger typed in mm still fires on the rise in mm."""
    y = 2
    post(client, f"/api/axes/{y}/move", {"value": 0.0, "unit": "mm"})
    wait_until(lambda: abs(user_position(client, y)) < 0.01, timeout=20, what="y at 0")
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        page.send({"type": "scope", "settings": {
            "channels": [{"axis": y, "signal": "position"}], "window_s": 0.5,
            "mode": "single", "edge": "rising", "level": 5.0, "pre": 0.5, "width": 200}})
        page.until(lambda: (s := page.last("scope_state")) and s["waiting"], "armed")
        post(client, f"/api/axes/{y}/move", {"value": 10.0, "unit": "mm"})
        frame = page.until(lambda: next((f for f in page.frames
                                         if f.flags & frames.FLAG_TRIGGERED), None),
                           "the triggered capture")
        at_zero = min(range(len(frame.x)), key=lambda i: abs(frame.x[i]))
        assert frame.ys[0][at_zero] == pytest.approx(5.0, abs=1.0)
        seen = [v for v in frame.ys[0] if math.isfinite(v)]
        assert seen[0] < 5.0 < seen[-1]  # rising, in mm
    wait_until(lambda: abs(user_position(client, y) - 10.0) < 0.01, timeout=20, what="at 10")


def test_step_and_wave_in_mm(client: TestClient) -> None:
    move_to(client, 0.0)
    info = client.get("/api/info").json()["axes"][0]
    r = post(client, f"/api/axes/{X}/tuning/step",
             {"distance": 2.0, "unit": "mm", "duration_s": 0.4})
    assert (r["unit"], r["name"]) == ("mm", "axis x")
    assert r["step"] == pytest.approx(2.0, abs=1e-3)  # whole counts: 2 mm as commanded
    assert r["distance"] == round(2.0 * info["counts_per_unit"])
    assert r["metrics"]["target"] - r["metrics"]["start"] == pytest.approx(2.0, abs=1e-3)
    assert max(p for p in r["trace"]["position"] if p is not None) == pytest.approx(2.0, abs=0.2)
    # the wave's amplitude in mm, checked against the soft limit at -10 mm from 2 mm
    wave = f"/api/axes/{X}/wave"
    refused = post(client, wave, {"kind": "sine", "amplitude": 15.0, "unit": "mm", "hz": 2},
                   400)
    assert "soft limits" in refused["error"]
    wrong = post(client, wave, {"kind": "sine", "amplitude": 1.0, "unit": "deg", "hz": 2}, 400)
    assert "in mm, not deg" in wrong["error"]
    post(client, wave, {"kind": "sine", "amplitude": 1.0, "unit": "mm", "hz": 2})
    post(client, wave, {"kind": "off"})
    post(client, f"/api/axes/{X}/command", {"action": "stop"})


#: What a Python repr looks like in a line: ``Name(``, ``<Enum.X: 0>``, ``b'...'``.
REPR = re.compile(r"[A-Za-z_]\(|<\w+\.\w+: |\bb'")


def test_the_traffic_log_is_one_decoded_line_per_transaction(client: TestClient) -> None:
    def lines() -> list[dict[str, Any]]:
        traffic: list[dict[str, Any]] = client.get("/api/diagnostics").json()["traffic"]
        return traffic

    # the status monitor reads every axis: DMM DYN232M (x, y) and YZ-AIM EasyCan (c)
    seen = wait_until(lambda: (t := lines()) and any("WRITE" in x["text"] or "READ" in x["text"]
                                                     for x in t if "->" in x["text"]) and t,
                      timeout=20, what="traffic of every link")
    assert all(not REPR.search(x["text"]) for x in seen), [x["text"] for x in seen][:5]
    pairs = [x for x in seen if x["dir"] == "pair"]
    assert pairs and all("  =>  " in x["text"] for x in pairs)
    assert len(pairs) > len(seen) / 2  # a read is one line with its answer


def test_ethernet_ip_traffic_in_the_sniff_decoders_words() -> None:
    from servobus.axis.connect import connect_async
    from servobus.gui.traffic import TrafficLog

    async def run() -> list[dict[str, object]]:
        axis = await connect_async("sim://enip?fast=1", drive_id=1)
        try:
            log = TrafficLog()
            await axis.add_trace(log.hook_for(axis))
            await axis.position()
            await axis.move_by(100)
            return log.recent(50, now=math.inf)
        finally:
            await axis.close()

    shown = [str(x["text"]) for x in asyncio.run(run())]
    assert shown and not [t for t in shown if REPR.search(t)], shown
    assert any(t.startswith("SET_ATTRIBUTE_SINGLE") and "go_relative_pos" in t and
               "=>  reply SET_ATTRIBUTE_SINGLE: ok" in t for t in shown), shown


def test_favicon_and_an_owner_refusal_that_says_who(client: TestClient) -> None:
    icon = client.get("/favicon.ico")
    assert icon.status_code == 200 and icon.headers["content-type"] == "image/svg+xml"
    assert client.get("/static/favicon.svg").status_code == 200
    move_to(client, 0.0)
    with client.websocket_connect(WS) as ws1, client.websocket_connect(WS) as ws2:
        first, second = Page(ws1), Page(ws2)
        owner = first.until(lambda: first.last("hello"), "hello")["owner"]
        second.until(lambda: second.last("hello"), "hello")
        first.send({"type": "jog", "axis": X, "speed": 5.0})
        first.until(lambda: (s := first.last("status")) and s["leases"].get(str(X)), "jogging")
        second.send({"type": "jog", "axis": X, "speed": 5.0})
        refusal = second.until(lambda: second.last("error"), "the refusal")
        assert f"axis x is held by page {owner}" in refusal["message"]
        first.send({"type": "jog_stop", "axis": X})
