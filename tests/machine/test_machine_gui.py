"""The GUI on a mixed machine, in-process: every axis of both links, named, in its units,
limits, STOP ALL, and one scope over axes of different protocols."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from machine_rig import write_machine
from rig import wait_until
from starlette.testclient import TestClient

from servobus.gui import frames
from servobus.gui.app import create_app

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    with TestClient(create_app(machine=write_machine(tmp_path)), base_url=BASE) as c:
        wait_until(lambda: all("user_position" in a["status"]
                               for a in c.get("/api/axes").json()),
                   what="first status of every axis")
        yield c


def status(client: TestClient, axis: int) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[axis - 1]["status"]
    return doc


def test_every_axis_of_both_links_named_in_its_unit(client: TestClient) -> None:
    info = client.get("/api/info").json()
    assert info["machine"] == "test-cell"
    axes = info["axes"]
    assert [(a["id"], a["name"], a["unit"], a["protocol"], a["drive_id"]) for a in axes] == [
        (1, "x", "mm", "dyn232", 1), (2, "y", "mm", "dyn232", 2), (3, "c", "deg", "easycan", 1)]
    assert axes[0]["limits"] == [-10.0, 300.0] and axes[0]["counts_per_unit"] == 65536 / 5
    assert status(client, 3)["unit"] == "deg" and status(client, 3)["speed_unit"] == "deg/s"


def test_moves_in_the_axis_unit_inside_the_limits(client: TestClient) -> None:
    r = client.post("/api/axes/1/move", json={"value": 12.5, "unit": "mm"})
    assert r.status_code == 200, r.text
    assert r.json()["counts"] == 163840
    wait_until(lambda: abs(status(client, 1)["user_position"] - 12.5) < 0.01
               and not status(client, 1)["moving"], timeout=10, what="x at 12.5 mm")
    r = client.post("/api/axes/3/move", json={"value": 721, "unit": "deg"})
    assert r.status_code == 400 and "soft limits" in r.json()["error"]
    assert not status(client, 3)["moving"] and abs(status(client, 3)["position"]) <= 2


def test_stop_all_stops_every_axis_of_every_link(client: TestClient) -> None:
    # Constant speed is a lease owned by the page that started it and renewed over its
    # WebSocket (issue 27; it used to be an open-ended turn): a page holds all three, and
    # STOP ALL wins over its renewals, which are refused from then on.
    with client.websocket_connect(WS) as ws:
        page = json.loads(ws.receive_text())["owner"]
        start = {a: status(client, a)["position"] for a in (1, 2, 3)}
        for axis in (1, 2, 3):
            r = client.post(f"/api/axes/{axis}/turn", json={"rpm": 60, "page": page})
            assert r.status_code == 200 and r.json()["open_ended"] is False, r.text

        def turning() -> bool:  # Run again renews (and restarts one a slow poll let lapse)
            for axis in (1, 2, 3):
                client.post(f"/api/axes/{axis}/turn", json={"rpm": 60, "page": page})
            return all(abs(status(client, a)["position"] - start[a]) > 20000 for a in (1, 2, 3))

        wait_until(turning, timeout=10, what="all turning")
        answer = client.post("/api/stop_all", json={}).json()
        assert answer["failed"] == [] and set(answer["axes"]) == {"1", "2", "3"}
        ws.send_text(json.dumps({"type": "turn", "axis": 1, "rpm": 60}))  # a late renewal
        wait_until(lambda: all(abs(status(client, a)["speed"]) < 1 for a in (1, 2, 3))
                   and not client.get("/api/diagnostics").json()["jog"]["active"],
                   timeout=10, what="all stopped")


def test_one_scope_plots_axes_of_two_protocols(client: TestClient) -> None:
    with client.websocket_connect(WS) as ws:
        ws.send_text(json.dumps({"type": "scope", "settings": {
            "channels": [{"axis": 1, "signal": "position"}, {"axis": 3, "signal": "position"}],
            "window_s": 0.5, "mode": "roll", "width": 200}}))
        client.post("/api/axes/3/move", json={"value": 90, "unit": "deg"})
        seen: list[frames.ScopeFrame] = []
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            message = ws.receive()
            if message.get("bytes") is None:
                continue
            frame = frames.decode(message["bytes"])
            ws.send_text(json.dumps({"type": "ack", "seq": frame.seq}))
            seen.append(frame)
            ys = [[v for v in y if math.isfinite(v)] for y in frame.ys]
            # the scope speaks the axis's unit (issue 33): c is in deg, 8 counts ~ 0.09 deg
            if len(ys) == 2 and ys[1] and abs(ys[1][-1] - 90) <= 0.09:
                break
        else:
            pytest.fail("no frame showing the c axis (EasyCan) at 90 deg")
        assert len(seen[-1].ys) == 2 and any(math.isfinite(v) for v in seen[-1].ys[0])


def test_servobus_gui_machine_serves_both_links(tmp_path: Path) -> None:
    import re
    import signal
    import subprocess
    import sys
    import urllib.request

    m = write_machine(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "gui", "--machine", str(m),
                             "--port", "0", "--no-browser"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first, second = proc.stdout.readline(), proc.stdout.readline()
        url = re.search(r"http://\S+", first)
        assert url is not None, (first, second)
        assert "machine test-cell" in second and "axes 1 x, 2 y, 3 c" in second
        with urllib.request.urlopen(url.group(0) + "api/info", timeout=5) as r:
            info = json.loads(r.read())
        assert [(a["name"], a["protocol"]) for a in info["axes"]] == [
            ("x", "dyn232"), ("y", "dyn232"), ("c", "easycan")]
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=10)
    # Ctrl-C ends a server normally: exit 0 and one stdout line (issue 17.8, docs/gui.md)
    assert proc.returncode == 0 and err == "", err
    assert out.strip().splitlines()[-1].startswith("servobus gui: Ctrl-C: every axis was stopped")


def test_an_offline_axis_shows_its_link_error_and_stop_all_goes_on(tmp_path: Path) -> None:
    import machine_rig

    from servobus.axis import registry

    registry.register("flaky", "machine_rig:flaky_open")
    machine_rig.FLAKY.update(down=True, attempts=0)
    text = machine_rig.MIXED + '\n[axes.z]\nurl = "flaky://line"\nid = 3\nunit = "rev"\n'
    with TestClient(create_app(machine=write_machine(tmp_path, text)), base_url=BASE) as c:
        info = c.get("/api/info").json()
        z = info["axes"][3]
        assert (z["name"], z["online"], z["family_title"]) == ("z", False, "offline")
        wait_until(lambda: "offline" in status(c, 4).get("link", ""), what="z's link error")
        answer = c.post("/api/stop_all", json={}).json()
        assert answer["failed"] == [4] and "offline" in answer["axes"]["4"]
        r = c.get("/api/axes/4/params")  # a page asking the offline axis: a typed answer
        assert r.status_code == 503 and "axis z is offline (flaky://line)" in r.json()["error"]
        machine_rig.FLAKY["down"] = False
        wait_until(lambda: "position" in status(c, 4) and not status(c, 4)["link"],
                   timeout=10, what="z back online")
        assert status(c, 4)["unit"] == "rev"
