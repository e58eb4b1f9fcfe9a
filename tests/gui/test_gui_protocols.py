"""The scope's sampler and the step test on every sim:// protocol, in-process (issue 17.2).

Two axes per connection: on YZ-AIM (EasyCan, Modbus) the motors' core drives all have id 0,
which once made ``trace_buffer()`` fail and the sampler die silently (the step test then
answered 504). A sampler whose trace fails in any way polls instead and says why; one that
stops says why, and the step test answers with that at once.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from rig import wait_until
from starlette.testclient import TestClient

from servobus.errors import DriveTimeout
from servobus.gui.app import create_app
from servobus.gui.state import GuiState

pytestmark = pytest.mark.timeout(60)
BASE = "http://127.0.0.1:8080"
URLS = ["sim://dyn232?fast=1", "sim://dyncan?fast=1", "sim://enip?fast=1",
        "sim://easycan?fast=1", "sim://modbus?fast=1"]


@contextmanager
def gui_on(url: str) -> Iterator[TestClient]:
    with TestClient(create_app(url, [1, 2]), base_url=BASE) as c:
        wait_until(lambda: all("position" in a["status"] for a in c.get("/api/axes").json()),
                   timeout=10, what="first status of every axis")
        yield c


def gui_state(client: TestClient) -> GuiState:
    state: GuiState = client.app.state.gui  # type: ignore[attr-defined]
    return state


def step(client: TestClient, axis: int, code: int = 200) -> dict[str, Any]:
    r = client.post(f"/api/axes/{axis}/tuning/step",
                    json={"distance": 18, "unit": "deg", "duration_s": 0.4})
    assert r.status_code == code, r.text
    doc: dict[str, Any] = r.json()
    return doc


@pytest.mark.parametrize("url", URLS)
def test_the_step_test_reads_the_drive_trace_of_either_axis(url: str) -> None:
    with gui_on(url) as client:
        rev = client.get("/api/info").json()["axes"][1]["counts_per_rev"]
        result = step(client, 2)
        m = result["metrics"]
        assert result["source"] == "trace" and result["rate_hz"] == 4000.0
        assert result["samples"] >= 0.4 * 4000 * 0.9
        assert m["target"] - m["start"] == round(rev / 20)  # 18 degrees
        assert m["rise_time_s"] is not None and m["following_error_max"] > 0
        sampler = gui_state(client).samplers[2]
        assert sampler.error == "" and sampler.source == "trace"
        # the trace shows the drive's own position, in the axis's counts
        assert abs(result["trace"]["position"][-1] - (m["target"] - m["start"])) < 0.01 * rev


def test_a_trace_that_fails_in_any_way_falls_back_to_polling_and_says_so() -> None:
    with gui_on("sim://dyn232?fast=1") as client:
        axis = gui_state(client).fleet.get(1).axis

        async def broken() -> None:
            raise RuntimeError("trace reader bug")

        axis.trace_buffer = broken  # type: ignore[assignment,method-assign]
        result = step(client, 1)
        assert result["source"] == "poll" and result["samples"] > 10
        sampler = gui_state(client).samplers[1]
        assert sampler.describe()["error"] == ("trace: RuntimeError: trace reader bug; "
                                               "polling instead")


def test_a_sampler_that_stops_says_why_and_the_step_test_answers_with_it() -> None:
    with gui_on("sim://dyn232?fast=1") as client:
        sampler = gui_state(client).samplers[1]

        async def dead() -> None:
            raise AssertionError("unreachable")

        sampler.handle.axis.trace_buffer = dead  # type: ignore[assignment,method-assign]

        async def poll_bug() -> None:
            raise KeyError("poll bug")

        sampler._run_poll = poll_bug  # type: ignore[method-assign]
        doc = step(client, 1, 502)
        assert doc["error"] == "no samples: sampling stopped: KeyError: 'poll bug'"
        state = sampler.describe()
        assert not state["running"] and "sampling stopped: KeyError" in str(state["error"])
        assert DriveTimeout.__name__ not in doc["kind"]
