"""The sampler's own log lines (servobus.gateway.sampler): "no readings" when an online
axis's readings turn Bad, "readings are back" only after that line; a spell that goes
offline is the machine's to tell. Samples are handed to the sampler as its loop would."""

from __future__ import annotations

import logging

import pytest
from fake_machine import FakeMachine

from servobus.gateway.sampler import BAD_AFTER, Health, Sample, Sampler

ONLINE, OFFLINE = Health(online=True), Health(online=False)


def good() -> Sample:
    return Sample("a0", 0.0, True, position=1.0, health=ONLINE)


def bad(health: Health, error: str = "no reply") -> Sample:
    return Sample("a0", 0.0, False, error, health=health, code="BadTimeout")


def lines(caplog: pytest.LogCaptureFixture, samples: list[Sample]) -> list[str]:
    sampler = Sampler(FakeMachine("lines"), 50)  # type: ignore[arg-type]
    caplog.clear()
    for sample in samples:
        sampler._publish(sample)
    return [r.getMessage() for r in caplog.records if r.name == "servobus.gateway.sampler"]


@pytest.fixture(autouse=True)
def _info(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="servobus.gateway.sampler")


def test_a_bad_spell_online_has_its_two_lines(caplog: pytest.LogCaptureFixture) -> None:
    assert lines(caplog, [good(), *[bad(ONLINE)] * BAD_AFTER, good()]) == [
        "axis a0: no readings: no reply", "axis a0: readings are back"]


def test_a_spell_that_began_offline_ends_without_a_line_of_ours(
        caplog: pytest.LogCaptureFixture) -> None:
    # the link dropped (the machine's line), came back, and the first read after it timed
    # out (online again): the readings coming back are the link's "online" line, not ours
    assert lines(caplog, [good(), bad(OFFLINE, "offline"), bad(ONLINE), good()]) == []


def test_a_spell_that_went_offline_ends_without_a_back_line(
        caplog: pytest.LogCaptureFixture) -> None:
    assert lines(caplog, [good(), *[bad(ONLINE)] * BAD_AFTER, bad(OFFLINE, "offline"),
                          good()]) == ["axis a0: no readings: no reply"]
