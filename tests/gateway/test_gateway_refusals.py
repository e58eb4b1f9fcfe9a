"""One log line per spell of refused commands (servobus.gateway.refusals): a flood of refused
MQTT or OPC UA commands is answered one by one but logged once per source per spell."""

from __future__ import annotations

import asyncio
import logging

import pytest
from fake_machine import FakeMachine

from servobus.gateway.commands import Command, Commander, Refused
from servobus.gateway.refusals import RefusalLog


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_spell_is_one_line_and_the_next_line_counts_what_was_left_out() -> None:
    clock = Clock()
    spells = RefusalLog(spell_s=10.0, clock=clock)
    assert spells.admit("mqtt gate") == ""
    assert [spells.admit("mqtt gate") for _ in range(999)] == [None] * 999
    assert spells.admit("opcua bob") == ""  # another source has its own spell
    clock.now += 10.0
    assert spells.admit("mqtt gate") == "; and 999 more refused in the 10 s before"
    assert spells.admit("mqtt gate") is None


def test_the_sources_remembered_are_bounded() -> None:
    spells = RefusalLog(max_sources=4, clock=Clock())
    for n in range(100):
        assert spells.admit(f"user{n}") == ""
    assert len(spells) == 4


def test_a_flood_of_refused_commands_is_answered_each_and_logged_once(
        caplog: pytest.LogCaptureFixture) -> None:
    commander = Commander(FakeMachine())  # type: ignore[arg-type]
    refused = 0

    async def flood() -> None:
        nonlocal refused
        for _ in range(500):
            with pytest.raises(Refused):  # anonymous: refused before anything moves
                await commander.run(None, Command("x", "enable"), "mqtt")
            refused += 1

    with caplog.at_level(logging.WARNING, logger="servobus.gateway"):
        asyncio.run(flood())
    assert refused == 500
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(lines) == 1 and "BadUserAccessDenied" in lines[0]
