"""The GUI's status lights follow the one meaning of moving / in position (docs/axis.md,
"Moving and in position"): lit "moving" and dark "in position" while the motor turns, in
constant speed (jog) and in a drive-generated wave, on the status the page is sent."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from rig import wait_until
from starlette.testclient import TestClient

from servobus.gui.app import create_app

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"


@pytest.fixture
def client() -> Iterator[TestClient]:
    with TestClient(create_app(), base_url=BASE) as c:
        wait_until(lambda: all("position" in a["status"] for a in c.get("/api/axes").json()),
                   what="first status of every axis")
        yield c


def status(client: TestClient, axis: int) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[axis - 1]["status"]
    return doc


def post(client: TestClient, path: str, doc: object) -> None:
    r = client.post(path, json=doc)
    assert r.status_code == 200, r.text


def snapshot_while_turning(client: TestClient, axis: int, rpm: float) -> dict[str, Any]:
    """A status snapshot taken while the motor turns at |speed| >= rpm."""
    found: list[dict[str, Any]] = []

    def turning() -> bool:
        s = status(client, axis)
        if abs(s["speed"]) >= rpm:
            found.append(s)
        return bool(found)

    wait_until(turning, timeout=10, what=f"axis {axis} turning at {rpm} rpm or more")
    return found[0]


def test_constant_speed_is_moving_and_not_in_position(client: TestClient) -> None:
    post(client, "/api/axes/1/turn", {"rpm": 1950})
    s = snapshot_while_turning(client, 1, 1900)
    assert s["moving"] is True and s["in_position"] is False, s
    post(client, "/api/stop_all", {})
    wait_until(lambda: (st := status(client, 1))["in_position"] and not st["moving"],
               timeout=10, what="at rest again")


def test_a_wave_is_moving(client: TestClient) -> None:
    post(client, "/api/axes/2/wave", {"kind": "sine", "amplitude": 1000, "hz": 2})
    s = snapshot_while_turning(client, 2, 20)  # the sine peaks near 50 rpm
    assert s["moving"] is True and s["in_position"] is False, s
    post(client, "/api/stop_all", {})
