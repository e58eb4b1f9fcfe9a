"""The GUI shows what it knows (issue 29), in-process: every axis's state carries the
machine's link state (``online``, ``last_good``, ``interrupted``, ``power_lost``) and the age
of its values; a dropped link keeps the last values with their age, motion is a typed
refusal, the link comes back by itself, and motion waits for ``acknowledge`` (a command
like the others: token, JSON). The drop is a call finding the link lost
(``AsyncMachineAxis.link_lost``, what the machine hears from a failed call); the
``flaky://`` scheme (machine_rig) keeps the link down while the test wants it down, and
reopens it on a fresh in-process virtual line, as a drive that was power-cycled."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import machine_rig
import pytest
from drive_process_rig import procs as procs  # the fixture, for this module
from drive_process_rig import sim_url, start_sim
from machine_rig import write_machine
from rig import free_port, wait_until
from starlette.testclient import TestClient
from subprocess_rig import read_line, stop_process

from servobus.axis import registry
from servobus.errors import ConnectionLost
from servobus.gui.app import create_app
from servobus.machine import AsyncMachine, AsyncMachineAxis

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
COUNTS_PER_REV = 65536  # DYN232M (the flaky line is a virtual DYN232M line)
NEAR = COUNTS_PER_REV / 100  # a servo at rest rings within its in-position window


@pytest.fixture
def flaky_file(tmp_path: Path) -> Iterator[Path]:
    registry.register("flaky", "machine_rig:flaky_open")
    machine_rig.FLAKY.update(down=False, attempts=0)
    yield write_machine(tmp_path, '[axes.z]\nurl = "flaky://line"\nid = 1\nunit = "rev"\n')
    machine_rig.FLAKY["down"] = False


def state(client: TestClient) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[0]["status"]
    return doc


def events(caplog: pytest.LogCaptureFixture) -> list[str]:
    """servobus's log lines at INFO and above (what ``servobus gui`` prints on stderr)."""
    return [r.getMessage() for r in caplog.records
            if r.levelno >= logging.INFO and r.name.startswith("servobus")]


async def cut(axis: AsyncMachineAxis) -> None:
    """A call on the axis found its link lost (run on the app's loop)."""
    axis.link_lost(ConnectionLost("cable pulled (test)"), axis.axis)


def test_a_dropped_link_keeps_its_values_aged_and_motion_waits_for_acknowledge(
        flaky_file: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG, logger="servobus")
    app = create_app(machine=flaky_file)
    with TestClient(app, base_url=BASE) as c:
        wait_until(lambda: state(c).get("t"), what="a first reading")
        s = state(c)
        assert (s["online"], s["power_lost"], s["interrupted"]) == (True, False, None)
        assert isinstance(s["last_good"], float) and abs(s["last_good"] - time.time()) < 30
        assert s["stale_after_s"] >= 0.2 and s["age_s"] >= 0
        wait_until(lambda: not state(c)["stale"], what="a fresh reading")
        assert c.post("/api/axes/1/move", json={"value": 2, "unit": "rev"}).status_code == 200
        wait_until(lambda: abs(state(c)["user_position"] - 2) < 0.01 and not state(c)["moving"],
                   timeout=10, what="z at 2 rev")

        machine: AsyncMachine = app.state.gui.fleet.machine
        machine_rig.FLAKY["down"] = True
        caplog.clear()
        tries = machine.reconnect_tries
        assert c.portal is not None
        c.portal.call(cut, machine["z"])
        wait_until(lambda: state(c)["online"] is False and state(c)["link"],
                   what="z offline, its link error shown")
        dropped = state(c)
        assert dropped["last_good"] is not None
        assert abs(dropped["position"] - 2 * COUNTS_PER_REV) < NEAR  # the last value kept ...
        assert dropped["stale"]  # offline: stale at once ...
        wait_until(lambda: state(c)["age_s"] > state(c)["stale_after_s"],
                   what="the kept value older than two polling periods")  # ... with its age
        r = c.post("/api/axes/1/move", json={"value": 1, "unit": "rev"})
        assert r.status_code == 503 and r.json()["kind"] == "MachineLinkError", r.text
        wait_until(lambda: machine.reconnect_tries >= tries + 3, timeout=30,
                   what="three reconnect tries")
        down = events(caplog)
        assert len(down) == 1 and "is down" in down[0], down  # not one line per try

        caplog.clear()
        machine_rig.FLAKY["down"] = False  # back, on a fresh virtual drive
        wait_until(lambda: state(c)["online"] and state(c)["power_lost"], timeout=30,
                   what="z online again, flagged")
        wait_until(lambda: state(c)["t"] > dropped["t"], what="a reading after the reopen")
        back = state(c)
        assert abs(back["position"]) < NEAR, "nothing re-sent: the drive stands at power-up"
        assert "position moved" in back["power_lost_reason"]
        assert back["last_good"] > dropped["last_good"] and not back["link"]
        r = c.post("/api/axes/1/move", json={"value": 1, "unit": "rev"})
        assert r.status_code == 409 and r.json()["kind"] == "PowerLostError", r.text

        sent = c.get("/api/diagnostics").json()["traffic_counts"]["tx"]
        wait_until(lambda: c.get("/api/diagnostics").json()["traffic_counts"]["tx"] > sent,
                   what="the reopened link's traffic in Diagnostics")
        r = c.post("/api/axes/1/acknowledge", json={})
        assert r.status_code == 200 and r.json()["status"]["power_lost"] is False, r.text
        assert state(c)["power_lost_reason"] is None and state(c)["interrupted"] is None
        assert c.post("/api/axes/1/move", json={"value": 1, "unit": "rev"}).status_code == 200
        wait_until(lambda: abs(state(c)["user_position"] - 1) < 0.01, timeout=10,
                   what="z at 1 rev")
        lines = events(caplog)
        assert len(lines) == 3 and len(set(lines)) == 3, lines  # online, power, acknowledged
        kinds = [e["kind"] for e in c.get("/api/diagnostics").json()["alarms"]]
        assert kinds.count("power") == 1 and kinds.count("ack") == 1


def test_acknowledge_is_a_command_like_the_others() -> None:
    with TestClient(create_app(token="s3cret"), base_url="http://192.0.2.7:8080") as c:
        assert c.post("/api/axes/1/acknowledge", json={}).status_code == 401
        r = c.post("/api/axes/1/acknowledge", json={}, headers={"x-servobus-token": "s3cret"})
        assert r.status_code == 200 and r.json()["status"]["power_lost"] is False
    with TestClient(create_app(), base_url=BASE) as c:
        r = c.post("/api/axes/1/acknowledge", content=b"{}",
                   headers={"content-type": "text/plain"})  # what a foreign form can send
        assert r.status_code == 415
        r = c.post("/api/axes/1/acknowledge", json={}, headers={"host": "evil.example:8080"})
        assert r.status_code == 403
        assert c.post("/api/axes/9/acknowledge", json={}).status_code == 400


# ------------------------------------------------------------ real processes
def http(base: str, path: str, body: object | None = None) -> tuple[int, Any]:
    """(status, JSON answer) of a GET, or of a JSON POST when ``body`` is given."""
    request = urllib.request.Request(base + path)
    if body is not None:
        request.data = json.dumps(body).encode()
        request.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


@pytest.mark.slow
def test_a_gui_over_a_killed_and_restarted_drive(
        tmp_path: Path, procs: list[subprocess.Popen[str]]) -> None:
    """``servobus gui --machine`` over a DYN232M virtual drive in its own process: the drive
    killed mid-move and started again on its port. Offline with ``last_good``, motion a
    typed 503; online again by itself, flagged; acknowledged, a move works; the motion cut
    short is not re-sent; stderr has one line per event."""
    port = free_port()
    procs.append(start_sim("dyn232", port))
    path = write_machine(tmp_path, f'[axes.a]\nurl = "{sim_url("dyn232", port)}"\nid = 1\n'
                                   'unit = "rev"\n')
    gui = subprocess.Popen([sys.executable, "-m", "servobus", "gui", "--machine", str(path),
                            "--port", "0", "--no-browser"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(gui)
    base = read_line(gui, "servobus gui: http://").split()[-1]

    def status() -> dict[str, Any]:
        doc: dict[str, Any] = http(base, "api/axes")[1][0]["status"]
        return doc

    wait_until(lambda: status().get("t"), timeout=20, what="a first reading")
    code, _ = http(base, "api/axes/1/move", {"value": 50, "unit": "rev"})
    assert code == 200  # long enough to be running when the drive dies
    wait_until(lambda: status()["moving"], timeout=10, what="a moving")
    procs[0].kill()
    wait_until(lambda: not status()["online"], timeout=30, what="a offline")
    dropped = status()
    assert dropped["last_good"] is not None and dropped["interrupted"]
    code, doc = http(base, "api/axes/1/move", {"value": 1, "unit": "rev"})
    assert code == 503 and doc["kind"] == "MachineLinkError", doc

    procs.append(start_sim("dyn232", port))
    wait_until(lambda: status()["online"] and status()["power_lost"], timeout=60,
               what="a online again, flagged")
    wait_until(lambda: status()["t"] > dropped["t"], timeout=10, what="a reading after")
    assert abs(status()["position"]) < NEAR, "the cut motion was re-sent"
    code, doc = http(base, "api/axes/1/move", {"value": 1, "unit": "rev"})
    assert code == 409 and doc["kind"] == "PowerLostError", doc
    code, doc = http(base, "api/axes/1/acknowledge", {})
    assert code == 200 and not doc["status"]["power_lost"], doc
    assert http(base, "api/axes/1/move", {"value": 1, "unit": "rev"})[0] == 200
    wait_until(lambda: abs(status()["user_position"] - 1) < 0.01 and not status()["moving"],
               timeout=20, what="a at 1 rev")

    # One line per event, none per reconnect try. A link may flap once more: while the
    # killed process dies its listening socket can still take a connection (the first
    # reconnect try is at once), which is then reset - a real second drop, logged as one.
    lines = stop_process(gui).splitlines()
    drops = sum("is down" in x for x in lines)
    assert drops in (1, 2) and sum("is online" in x for x in lines) == drops, lines
    assert sum("acknowledged" in x for x in lines) == 1, lines
    assert len(lines) <= 4 * drops + 1, lines  # down, interrupted, online, power; ack
