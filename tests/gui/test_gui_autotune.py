"""The Tuning tab's "Auto" (servobus.gui.autotune), in-process: the tuner run on a machine
axis by the page that owns it.

Axis x: a virtual DYN232M with a direct load at 10 x the rotor inertia (the default gains
overshoot about 20 %), 5 mm per revolution, limits -10 .. 300 mm; the test moves are a
quarter turn, 1.25 mm, each recorded for the tuner's 0.6 s (a shorter record puts the
settling into the hold the tuner measures vibration on: a record of 0.3 s saw a calm move
as vibrating). Axis t: the same, moved by no other test (the drive's Adaptive Tuning
learns the load over moves: a drive moved before overshoots less at the kept gains).
Axis e: a virtual DYN5 (gains in RAM), axis c: a YZ-AIM motor (saves on request), for the
confirmations only.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from machine.machine_rig import write_machine
from rig import wait_until
from starlette.testclient import TestClient, WebSocketTestSession

from servobus.gui.app import create_app

pytestmark = pytest.mark.timeout(120)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"
X, T, E, C = 1, 2, 3, 4
MM = 1.25  # a quarter turn
LEASE_S = 30.0
MACHINE = """\
name = "tune-cell"

[axes.x]
url = "sim://dyn232?fast=1&load=direct&inertia=10"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]

[axes.t]
url = "sim://dyn232?fast=1&load=direct&inertia=10"
id = 2
unit = "mm"
per_rev = 5.0

[axes.e]
url = "sim://enip?fast=1"
id = 1
unit = "deg"

[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
"""


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    path = write_machine(tmp_path_factory.mktemp("autotune"), MACHINE)
    with TestClient(create_app(machine=path, jog_lease_s=1.0), base_url=BASE) as c:
        # A run's lease, generous: this thread renews between blocking requests, on a
        # loaded host too (the test of a lapse sets its own).
        c.app.state.gui.autotune.lease_s = LEASE_S  # type: ignore[attr-defined]
        yield c


class Page:
    """A page on the WebSocket that renews its auto-tune run on every status (``renew``)."""

    def __init__(self, ws: WebSocketTestSession, renew: bool = True, axis: int = X) -> None:
        self.ws, self.renew, self.axis = ws, renew, axis
        self.status: dict[str, Any] = {}
        self.errors: list[dict[str, Any]] = []
        self.hello: int | None = None
        self.owner: int = self.until(lambda: self.hello, "hello")

    def send(self, doc: dict[str, object]) -> None:
        self.ws.send_text(json.dumps(doc))

    def until(self, predicate: Callable[[], Any], what: str, timeout: float = 60.0) -> Any:
        deadline = time.monotonic() + timeout
        while (value := predicate()) is None or value is False:
            assert time.monotonic() < deadline, f"not seen within {timeout} s: {what}"
            message = self.ws.receive()
            if message.get("text") is None:
                continue  # scope frames: no scope runs here
            doc = json.loads(message["text"])
            if doc["type"] == "hello":
                self.hello = doc["owner"]
            elif doc["type"] == "status":
                self.status = doc
                if self.renew:
                    self.send({"type": "tune_renew", "axis": self.axis})
            elif doc["type"] == "error":
                self.errors.append(doc)
        return value

    def run(self) -> dict[str, Any] | None:
        """This page's run of its axis (an earlier page's shows until this one starts)."""
        run: dict[str, Any] | None = self.status.get("tune", {}).get(str(self.axis))
        return run if run is not None and run["mine"] else None

    def moves(self, n: int) -> dict[str, Any]:
        """This page's run once it made ``n`` test moves; it must not have ended before."""
        run: dict[str, Any] = self.until(
            lambda: (r := self.run()) is not None and (r["trials"] >= n
                                                       or r["state"] != "running") and r,
            f"{n} test moves")
        assert run["state"] == "running", run["message"]
        return run

    def until_ended(self, what: str) -> dict[str, Any]:
        run: dict[str, Any] = self.until(
            lambda: (r := self.run()) is not None and r["state"] != "running" and r, what)
        return run


def post(client: TestClient, path: str, doc: object, code: int = 200) -> dict[str, Any]:
    r = client.post(path, json=doc)
    assert r.status_code == code, r.text
    result: dict[str, Any] = r.json()
    return result


def gains(client: TestClient, axis: int = X) -> dict[str, int]:
    return {g["name"]: g["value"]
            for g in client.get(f"/api/axes/{axis}/tuning").json()["gains"]}


def status(client: TestClient, axis: int = X) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[axis - 1]["status"]
    return doc


def at_rest(client: TestClient) -> None:
    wait_until(lambda: status(client)["speed"] == 0, timeout=20, what="x at rest")


def start(client: TestClient, page: Page, mm: float = MM,
          goal: str = "settling") -> dict[str, Any]:
    doc = {"distance": mm, "unit": "mm", "page": page.owner, "goal": goal}
    asked = post(client, f"/api/axes/{page.axis}/tuning/auto", doc)
    assert asked["started"] is False
    return post(client, f"/api/axes/{page.axis}/tuning/auto", {**doc, "confirmed": True})


def test_the_confirmation_names_the_axis_and_the_distance_and_moves_nothing(
        client: TestClient) -> None:
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        before = status(client)["position"]
        asked = post(client, f"/api/axes/{X}/tuning/auto",
                     {"distance": MM, "unit": "mm", "page": page.owner})
        assert asked["question"] == ("tune axis x: test moves between here and 1.25 mm away, "
                                     "gains raised until the motor vibrates; go?")
        assert "EEPROM" in asked["note"] and asked["can_save"] is False
        # beyond the soft limits, in the axis's unit: refused before anything moves
        refused = post(client, f"/api/axes/{X}/tuning/auto",
                       {"distance": 400.0, "unit": "mm", "page": page.owner,
                        "confirmed": True}, 400)
        assert "soft limits" in refused["error"] and "mm" in refused["error"]
        assert refused["kind"] == "LimitError"
        goal = post(client, f"/api/axes/{X}/tuning/auto",
                    {"distance": MM, "unit": "mm", "page": page.owner, "goal": "fast",
                     "confirmed": True}, 400)
        assert "goal 'fast'" in goal["error"] and goal["kind"] == "ArgumentRangeError"
        dyn5 = post(client, f"/api/axes/{E}/tuning/auto",
                    {"distance": 90.0, "unit": "deg", "page": page.owner})
        assert "DMMDRV5" in dyn5["save_hint"] and dyn5["note"] is None
        saved = post(client, f"/api/axes/{E}/tuning/auto",
                     {"distance": 90.0, "unit": "deg", "page": page.owner, "save": True}, 400)
        assert "not saved with a command" in saved["error"]
        yz = post(client, f"/api/axes/{C}/tuning/auto",
                  {"distance": 90.0, "unit": "deg", "page": page.owner, "save": True})
        assert yz["can_save"] is True and "90 deg" in yz["question"]
        assert client.get(f"/api/axes/{C}/tuning/auto").json()["can_save"] is True
        assert client.get(f"/api/axes/{E}/tuning/auto").json()["can_save"] is False
        assert status(client)["position"] == before
        assert client.get(f"/api/axes/{X}/tuning/auto").json()["run"] is None


def test_another_page_is_refused_and_cancel_stops_the_motor_and_reverts(
        client: TestClient) -> None:
    kept = gains(client)
    with client.websocket_connect(WS) as ws_a, client.websocket_connect(WS) as ws_b:
        a, b = Page(ws_a), Page(ws_b, renew=False)
        assert start(client, a, goal="stiffness")["run"]["goal"] == "stiffness"
        a.moves(2)
        # another page: no second run, no jog, no step test, no gains written
        other = post(client, f"/api/axes/{X}/tuning/auto",
                     {"distance": MM, "unit": "mm", "page": b.owner, "confirmed": True}, 409)
        assert f"page {a.owner}" in other["error"] and other["kind"] == "OwnerError"
        b.send({"type": "jog", "axis": X, "speed": 5.0})
        b.until(lambda: len(b.errors) >= 1, "the jog's refusal")
        assert "tuned" in b.errors[-1]["message"]
        assert post(client, f"/api/axes/{X}/tuning/step",
                    {"distance": MM, "unit": "mm"}, 409)["kind"] == "OwnerError"
        assert post(client, f"/api/axes/{X}/tuning/apply",
                    {"values": kept}, 409)["kind"] == "OwnerError"
        b.send({"type": "tune_renew", "axis": X})  # not its run: refused
        b.until(lambda: len(b.errors) >= 2, "the renewal's refusal")
        assert "not this page's" in b.errors[-1]["message"]
        cancelled = post(client, f"/api/axes/{X}/tuning/auto/cancel", {})["run"]
        assert cancelled["state"] == "stopped" and "kept gains" in cancelled["message"]
        assert gains(client) == kept
        at_rest(client)


def test_a_page_that_goes_away_aborts_its_run(client: TestClient) -> None:
    kept = gains(client)
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        start(client, page)
        page.moves(1)

    def run_ended() -> dict[str, Any] | None:  # the server ends the page after the socket closed
        run: dict[str, Any] = client.get(f"/api/axes/{X}/tuning/auto").json()["run"]
        return run if run["state"] != "running" else None

    run = wait_until(run_ended, timeout=30, what="the run's end after the page went away")
    assert run["state"] == "stopped" and "went away" in run["message"]
    assert gains(client) == kept
    at_rest(client)
    # a page still connected that stops renewing (a frozen tab): the run ends too
    autotune = client.app.state.gui.autotune  # type: ignore[attr-defined]
    autotune.lease_s = 1.0
    try:
        with client.websocket_connect(WS) as ws:
            frozen = Page(ws, renew=False)
            start(client, frozen)
            ended = frozen.until_ended("the run's end without renewals")
    finally:
        autotune.lease_s = LEASE_S
    assert ended["state"] == "stopped" and "renewing" in ended["message"]
    assert gains(client) == kept


def test_stop_all_cancels_a_run(client: TestClient) -> None:
    kept = gains(client)
    with client.websocket_connect(WS) as ws:
        page = Page(ws)
        start(client, page)
        page.moves(1)
        post(client, "/api/stop_all", {})
        ended = page.until_ended("the run's end after STOP ALL")
    assert ended["state"] == "stopped" and "kept gains" in ended["message"]
    assert gains(client) == kept
    at_rest(client)


@pytest.mark.slow  # a whole run: about 23 test moves of wall-clock motion
def test_a_run_to_completion_shows_the_table_and_reverts(client: TestClient) -> None:
    kept = gains(client, T)
    with client.websocket_connect(WS) as ws:
        page = Page(ws, axis=T)
        start(client, page)
        run = page.until_ended("the run's end")
    assert run["state"] == "done", run["message"]
    table = run["result"]
    before, after = table["before"], table["after"]
    assert before["overshoot_pct"] > 15.0 and after["overshoot_pct"] <= 10.0
    assert after["vibration"] < 0.05 and after["settling_s"] is not None
    assert before["following_error"] is not None and before["following_error"] < MM
    tuned = {g["name"]: g["tuned"] for g in table["gains"]}
    assert {g["name"]: g["kept"] for g in table["gains"]} == kept != tuned
    assert gains(client, T) == tuned and "EEPROM" in table["save_hint"]
    restored = post(client, f"/api/axes/{T}/tuning/auto/revert", {})["restored"]
    assert restored and gains(client, T) == kept
    assert client.get(f"/api/axes/{T}/tuning/auto").json()["run"]["reverted"] is True
