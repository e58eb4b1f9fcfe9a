"""The fault run's gateway part: ``--only`` picks what runs, and a gateway that stopped
serving, left a payload unanswered or answered one with an unexpected error is a MISS."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from benchmarks import verdict
from benchmarks.bench_faults import selected
from benchmarks.fault_gateway import HostileReport, print_hostile


@pytest.fixture(autouse=True)
def fresh() -> Iterator[None]:
    verdict.FIGURES.clear()
    yield
    verdict.FIGURES.clear()


def test_only_selects_the_link_faults_the_gateways_or_one_kind() -> None:
    assert selected(None) == ["link", "mqtt", "sessions", "logins"]
    assert selected(["hostile"]) == ["mqtt", "sessions", "logins"]
    assert selected(["logins", "link"]) == ["link", "logins"]


def test_a_gateway_that_stopped_serving_is_a_miss(capsys: pytest.CaptureFixture[str]) -> None:
    report = HostileReport(results=[
        {"kind": "hostile mqtt", "sent": 10, "answered": 9,
         "codes": {"BadDecodingError": 8, "BadInternalError": 1}, "serving": True,
         "seconds": 1.0, "log lines": 9, "process": True},
        {"kind": "session flood", "error": "ConnectionRefusedError: gone", "serving": False,
         "seconds": 0.5, "log lines": 0, "process": False},
    ], position=(False, "TimeoutError: "), axis="x", state_arrived=True, exit_code=1)
    print_hostile(report)
    out = capsys.readouterr().out
    assert "session flood  FAILED: ConnectionRefusedError: gone" in out
    assert "still serving yes" in out  # the MQTT kind itself still got its probe answered
    missed = sorted(f.name for f in verdict.FIGURES if not f.ok)
    assert missed == ["faults: gateway serving after each hostile kind and at the end",
                      "faults: hostile MQTT payloads answered",
                      "faults: hostile MQTT payloads answered BadInternalError"]
    assert "serving after each kind and at the end: 2/4" in out
