"""The Tuning tab's "Auto" after a run was killed (servobus.tune.kept): the next run is
refused before anything moves or is written, and Revert writes the killed run's kept gains
back. A virtual DYN232M drive in its own process (an in-process ``sim://`` drive dies with
its process: no record is kept for it)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from drive_process_rig import procs as procs
from drive_process_rig import sim_url, start_sim
from machine.machine_rig import write_machine
from rig import free_port, wait_until
from starlette.testclient import TestClient

from servobus.families.dmm.vocabulary import DmmFunction as F
from servobus.gui.app import create_app
from servobus.transport.base import Direction
from servobus.tune import kept

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]
BASE = "http://127.0.0.1:8080"
MOTION = {F.GO_ABSOLUTE_POS, F.MAKE_LINEAR_LINE, F.GO_RELATIVE_POS, F.MAKE_CIRCULAR_ARC,
          F.TURN_CONST_SPEED, F.SQUARE_WAVE, F.SIN_WAVE, F.SS_FREQUENCY}


@pytest.fixture
def client(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
           procs: list[subprocess.Popen[str]]) -> Iterator[tuple[TestClient, str]]:
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    port = free_port()
    procs.append(start_sim("dyn232", port))
    url = sim_url("dyn232", port)
    path = write_machine(tmp_path, f'name = "cell"\n[axes.x]\nurl = "{url}"\nid = 1\n'
                                   'unit = "rev"\n')
    with TestClient(create_app(machine=path), base_url=BASE) as c:
        wait_until(lambda: "position" in status(c), what="first status")
        yield c, url


def status(client: TestClient) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[0]["status"]
    return doc


def motion_sent(client: TestClient, after: int) -> list[object]:
    """Motion commands (DYN232M 7.2.4) the GUI's trace hook saw sent since entry ``after``
    (the position would not do: a gain just written settles the shaft by a count)."""
    traffic = client.app.state.gui.fleet.traffic  # type: ignore[attr-defined]
    return [e.item for e in list(traffic.entries)
            if e.seq > after and e.direction is Direction.TX
            and getattr(e.item, "function", None) in MOTION]


def last_seq(client: TestClient) -> int:
    entries = client.app.state.gui.fleet.traffic.entries  # type: ignore[attr-defined]
    return int(entries[-1].seq) if entries else 0


def gains(client: TestClient) -> dict[str, int]:
    return {g["name"]: g["value"] for g in client.get("/api/axes/1/tuning").json()["gains"]}


def test_a_killed_runs_record_refuses_auto_and_revert_writes_its_gains_back(
        client: tuple[TestClient, str]) -> None:
    c, url = client
    factory = gains(c)
    # a run killed after writing speed_gain under test: its record, its process gone
    record = kept.record_for(url, 1, "axis x")
    assert record is not None
    record.write(factory)
    doc = json.loads(record.path.read_text())
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    doc["pid"] = ended.pid
    record.path.write_text(json.dumps(doc))
    under_test = {"speed_gain": factory["speed_gain"] + 10}
    r = c.post("/api/axes/1/tuning/apply", json={"values": under_test})
    assert r.status_code == 200, r.text
    mark = last_seq(c)

    with c.websocket_connect("ws://127.0.0.1:8080/ws") as ws:
        page = wait_until(lambda: (m := json.loads(ws.receive_text()))["type"] == "hello"
                          and m["owner"], what="the page's hello")
        r = c.post("/api/axes/1/tuning/auto", json={"distance": 0.25, "unit": "rev",
                                                    "page": page, "confirmed": True})
        assert r.status_code == 200, r.text

        def ended_run() -> dict[str, Any] | None:
            run: dict[str, Any] | None = c.get("/api/axes/1/tuning/auto").json()["run"]
            return run if run is not None and run["state"] != "running" else None

        run = wait_until(ended_run, timeout=30, what="the run refused")  # the page still open
    assert run["state"] == "failed" and run["restorable"] is True
    assert "TuningInterrupted" in run["message"] and "Revert" in run["message"]
    assert run["trials"] == 0 and motion_sent(c, mark) == []
    assert gains(c) == {**factory, **under_test}  # nothing written

    r = c.post("/api/axes/1/tuning/auto/revert", json={})
    assert r.status_code == 200, r.text
    assert r.json()["restored"] == {"speed_gain": factory["speed_gain"]}
    assert gains(c) == factory and not record.path.exists()
    r = c.post("/api/axes/1/tuning/auto/revert", json={})  # nothing left to write back
    assert r.status_code == 400, r.text
