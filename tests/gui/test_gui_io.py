"""The I/O panel's server side in-process: virtual JP3 inputs and outputs over REST and the
WebSocket, the config endpoint, and AsyncAxis.virtual_io() on the sim:// drives."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rig import wait_until
from starlette.testclient import TestClient

from servobus.axis.connect import connect_async
from servobus.errors import ArgumentRangeError, NotSupported
from servobus.gui.app import create_app

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
WS = "ws://127.0.0.1:8080/ws"
REV = 65536


@pytest.fixture
def client() -> Iterator[TestClient]:
    with TestClient(create_app(), base_url=BASE) as c:
        wait_until(lambda: all("position" in a["status"] for a in c.get("/api/axes").json()),
                   what="first status of every axis")
        yield c


def post(client: TestClient, path: str, doc: object, code: int = 200) -> dict[str, Any]:
    r = client.post(path, json=doc)
    assert r.status_code == code, r.text
    result: dict[str, Any] = r.json()
    return result


def io(client: TestClient, axis: int) -> dict[str, Any]:
    r = client.get(f"/api/axes/{axis}/io")
    assert r.status_code == 200, r.text
    doc: dict[str, Any] = r.json()
    return doc


def status(client: TestClient, axis: int) -> dict[str, Any]:
    doc: dict[str, Any] = client.get("/api/axes").json()[axis - 1]["status"]
    return doc


# ------------------------------------------------------------------ REST
def test_identity_says_virtual_io_and_the_io_read_has_limits_outputs_state(
        client: TestClient) -> None:
    axes = client.get("/api/info").json()["axes"]
    assert [a["virtual_io"] for a in axes] == [True, True, True]
    doc = io(client, 2)
    assert doc["axis"] == 2 and doc["state"]["id"] == 2
    assert doc["limits"]["analog_v"] == [-12.0, 12.0]
    assert doc["limits"]["pulse_rate_hz"][1] == 500_000
    assert set(doc["limits"]["pulse_formats"]) == {"pulse_dir", "cw_ccw", "ab"}
    assert doc["outputs"]["alarm"] is False and doc["outputs"]["on_position"] is True
    assert doc["state"]["servo"] == "position" and doc["state"]["inputs"]["analog_v"] == 0.0


def test_analog_speed_mode_turns_the_motor_at_600_rpm_per_volt(client: TestClient) -> None:
    cfg = client.get("/api/axes/1/config").json()
    assert cfg["command_mode"] == "rs232" and "analog" in cfg["choices"]["command_mode"]
    done = post(client, "/api/axes/1/config", {"command_mode": "analog", "servo_mode": "speed"})
    assert done["changed"] and done["config"]["command_mode"] == "analog"
    assert done["config"]["servo_mode"] == "speed"
    again = post(client, "/api/axes/1/config", {"servo_mode": "speed"})
    assert not again["changed"]  # no second EEPROM write for the same config
    reply = post(client, "/api/axes/1/io", {"analog_v": 1.5})
    assert reply["state"]["inputs"]["analog_v"] == 1.5
    wait_until(lambda: abs(io(client, 1)["state"]["speed_rpm"] - 900) < 1, timeout=5,
               what="900 rpm from 1.5 V")
    wait_until(lambda: abs(status(client, 1)["speed"] - 900) < 5, timeout=5,
               what="the axis status sees it too")
    zri = io(client, 1)["outputs"]["zri_count"]
    wait_until(lambda: io(client, 1)["outputs"]["zri_count"] > zri, what="ZRI pulses")
    assert io(client, 2)["state"]["speed_rpm"] == 0  # the other drives keep still
    post(client, "/api/axes/1/io", {"analog_v": 0})
    wait_until(lambda: abs(io(client, 1)["state"]["speed_rpm"]) < 1, timeout=5, what="0 V stops")
    post(client, "/api/axes/1/config", {"command_mode": "rs232", "servo_mode": "position"})


def test_a_pulse_train_moves_by_four_times_gear_num_per_rev(client: TestClient) -> None:
    post(client, "/api/axes/3/config", {"command_mode": "pulse_dir"})
    gear = {p["name"]: p["value"] for p in
            client.get("/api/axes/3/params").json()["params"]}["gear_num"]
    start = io(client, 3)["state"]["position"]
    pulses = 2 * gear  # half a revolution (4 x GEAR_NUM pulses per rev, DYN2 4.1)
    reply = post(client, "/api/axes/3/io", {"pulses": {"count": pulses, "rate": 100_000}})
    train = reply["replies"]["pulses"]
    assert train["taken"] == pulses and not train["ignored"] and train["format"] == "pulse_dir"
    assert train["seconds"] == pytest.approx(pulses / 100_000)
    wait_until(lambda: abs(io(client, 3)["state"]["position"] - (start + REV // 2)) <= 2,
               timeout=5, what="half a revolution")
    post(client, "/api/axes/3/config", {"command_mode": "rs232"})
    ignored = post(client, "/api/axes/3/io", {"pulses": {"count": 100}})["replies"]["pulses"]
    assert ignored["ignored"] and ignored["taken"] == 0  # RS232 mode ignores the inputs


def test_ena_off_frees_the_motor_and_on_gives_it_back(client: TestClient) -> None:
    reply = post(client, "/api/axes/2/io", {"ena": False})
    assert reply["state"]["servo"] == "free" and reply["state"]["inputs"]["ena"] is False
    wait_until(lambda: not status(client, 2)["enabled"], what="status: disabled")
    reply = post(client, "/api/axes/2/io", {"ena": True})
    assert reply["state"]["servo"] == "position"
    wait_until(lambda: status(client, 2)["enabled"], what="status: enabled again")


@pytest.mark.parametrize("path,doc,words", [
    ("/api/axes/1/io", {"analog_v": 15}, "outside -12..12"),
    ("/api/axes/1/io", {"analog_v": "1"}, "finite number"),
    ("/api/axes/1/io", {"ena": 1}, "true or false"),
    ("/api/axes/1/io", {"volts": 1}, "unknown: volts"),
    ("/api/axes/1/io", {}, "give analog_v"),
    ("/api/axes/1/io", {"pulses": {"count": 10, "format": "morse"}}, "format must be one of"),
    ("/api/axes/1/io", {"pulses": {"count": 10, "rate": 600_000}}, "outside"),
    ("/api/axes/1/io", {"pulses": {"count": 1.5}}, "integer"),
    ("/api/axes/9/io", {"analog_v": 1}, "no axis 9"),
    ("/api/axes/1/config", {"command_mode": "telepathy"}, "one of rs232"),
    ("/api/axes/1/config", {"gear": 3}, "unknown: gear"),
])
def test_refusals_name_the_problem_and_change_nothing(client: TestClient, path: str,
                                                      doc: object, words: str) -> None:
    before = io(client, 1)["state"]["inputs"]
    answer = post(client, path, doc, 400)
    assert words in answer["error"]
    assert io(client, 1)["state"]["inputs"] == before


# ------------------------------------------------------------------ WebSocket
def test_the_page_watches_one_axis_live_over_the_websocket(client: TestClient) -> None:
    with client.websocket_connect(WS) as ws:
        ws.send_text(json.dumps({"type": "io_watch", "axis": 2}))
        post(client, "/api/axes/2/io", {"analog_v": 3.25})
        deadline = time.monotonic() + 5
        seen: dict[str, Any] = {}
        while time.monotonic() < deadline:
            doc = json.loads(ws.receive_text())
            if doc["type"] == "io":
                assert doc["axis"] == 2
                seen = doc
                if doc["state"]["inputs"]["analog_v"] == 3.25:
                    break
        assert seen["state"]["inputs"]["analog_v"] == 3.25 and "pins" in seen["outputs"]
        ws.send_text(json.dumps({"type": "io_watch", "axis": 7}))
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            doc = json.loads(ws.receive_text())
            if doc["type"] == "error":
                assert "no axis 7" in doc["message"] and doc["request"] == "io_watch"
                break
        else:
            pytest.fail("no error for an unknown axis")


# ------------------------------------------------------------------ without virtual I/O
def test_a_yzaim_motor_has_no_virtual_io_and_the_api_says_so() -> None:
    with TestClient(create_app("sim://easycan?fast=1", [1]), base_url=BASE) as c:
        assert c.get("/api/info").json()["axes"][0]["virtual_io"] is False
        r = c.get("/api/axes/1/io")
        assert r.status_code == 501 and "not a virtual drive" in r.json()["error"]
        assert c.post("/api/axes/1/io", json={"analog_v": 1}).status_code == 501
        assert c.get("/api/axes/1/config").status_code == 501  # no config byte on YZ-AIM


# ------------------------------------------------------------------ the Axis call
@pytest.mark.parametrize("url", ["sim://dyn232?fast=1&ids=1,2", "sim://dyncan?fast=1&ids=1,2"])
def test_virtual_io_of_siblings_reaches_their_own_drive(url: str) -> None:
    async def run() -> None:
        first = await connect_async(url, drive_id=1)
        second = await first.sibling(2)
        try:
            await second.virtual_io().set_analog(-2.0)
            assert (await second.virtual_io().state())["inputs"]["analog_v"] == -2.0
            assert (await first.virtual_io().state())["inputs"]["analog_v"] == 0.0
            with pytest.raises(ArgumentRangeError, match="outside"):
                await first.virtual_io().set_analog(20.0)
        finally:
            await second.close()
            await first.close()
    asyncio.run(run())


def test_a_yzaim_axis_raises_not_supported() -> None:
    async def run() -> None:
        axis = await connect_async("sim://modbus?fast=1", drive_id=1)
        try:
            with pytest.raises(NotSupported, match="not a virtual drive"):
                axis.virtual_io()
        finally:
            await axis.close()
    asyncio.run(run())
