"""Issue 32: ``servobus jog``, arrow keys from a terminal, leased motion.

The jogger (servobus.cli.jog_cmd.Jogger) runs on a scripted key source and a simulated
clock against a recording axis: what it calls when, with no wall-clock waits. The command
runs end to end on a pseudo-terminal (the terminal's mode restored afterwards) and on an
injected key source (Ctrl-C stops the motion, exit 130).
"""

from __future__ import annotations

import io
import json
import os
import pty
import sys
import termios
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType

import pytest
from cli_rig import no_env as no_env  # the fixture, for this module
from cli_rig import run
from rig import wait_until

from servobus.cli import failures as F
from servobus.cli import jog_cmd
from servobus.cli.failures import CliError
from servobus.cli.hold import RENEW_S, TTL_S
from servobus.cli.jog_cmd import Jogger
from servobus.cli.jog_keys import MINUS, OTHER, PLUS, QUIT, decode
from servobus.errors import LimitError
from servobus.machine.lease import Lease

SPEED = 20.0
RELEASE = 0.7
REPEAT_DELAY, REPEAT = 0.66, 1 / 30  # X11's defaults: a held key, as it arrives


# ------------------------------------------------------------------ key decoding
def test_arrow_keys_in_both_cursor_modes_and_the_rest() -> None:
    assert decode(b"\x1b[C\x1b[A\x1b[D\x1b[B") == [PLUS, PLUS, MINUS, MINUS]
    assert decode(b"\x1bOC\x1bOD") == [PLUS, MINUS]  # the terminal's application mode
    assert decode(b"q\x04Q") == [QUIT, QUIT, QUIT]
    assert decode(b" \x1b[H\x1b") == [OTHER, OTHER, OTHER]  # space, Home, a lone Esc


# ------------------------------------------------------------------ the jogger, scripted
@dataclass
class Clock:
    now: float = 0.0

    def __call__(self) -> float:
        return self.now


@dataclass
class Script:
    """Keys at given times on the simulated clock; ``read`` advances the clock to the next
    key, or by its timeout when none comes first."""

    clock: Clock
    keys: list[tuple[float, str]]
    waits: list[float | None] = field(default_factory=list)

    def read(self, timeout: float | None) -> str | None:
        self.waits.append(timeout)
        if not self.keys:
            if timeout is None:
                raise AssertionError("the jogger waits for ever at rest with no key to come")
            self.clock.now += timeout
            return None
        at, key = self.keys[0]
        if timeout is not None and at > self.clock.now + timeout:
            self.clock.now += timeout
            return None
        self.keys.pop(0)
        self.clock.now = max(self.clock.now, at)
        return key


@dataclass
class Recorder:
    """A machine axis that records the jogger's calls with the simulated time."""

    clock: Clock
    calls: list[tuple[float, str, float]] = field(default_factory=list)
    lease: Lease | None = None
    refuse: float | None = None  # heading (sign) at the soft limit
    renewals_end: bool = False

    def jog(self, speed: float | None = None, *, owner: str = "", ttl: float = 0.5) -> None:
        assert speed is not None and ttl == TTL_S and owner.startswith("servobus jog (pid ")
        if self.refuse is not None and speed * self.refuse > 0:
            raise LimitError("axis x is at 300 mm, at soft limit 300 mm; moving further out "
                             "is refused, nothing was sent")
        self.calls.append((self.clock.now, "jog", speed))

    def renew(self, owner: str, ttl: float = 0.5) -> bool:
        self.calls.append((self.clock.now, "renew", ttl))
        return not self.renewals_end

    def stop(self) -> None:
        self.calls.append((self.clock.now, "stop", 0.0))


def jogger(keys: list[tuple[float, str]]) -> tuple[Jogger, Recorder, Script, list[str]]:
    clock = Clock()
    axis, script, said = Recorder(clock), Script(clock, keys), []
    return Jogger(axis, SPEED, RELEASE, script, clock=clock, say=said.append,
                  speed_text="20 mm/s"), axis, script, said


def held(key: str, start: float, until: float) -> list[tuple[float, str]]:
    """A key held from ``start`` to ``until``: its key-down, then its auto-repeat."""
    times = [start]
    t = start + REPEAT_DELAY
    while t <= until:
        times.append(t)
        t += REPEAT
    return [(t, key) for t in times]


def test_a_held_key_jogs_and_stops_the_release_time_after_its_last_repeat() -> None:
    keys = held(PLUS, 1.0, 3.0)
    last = keys[-1][0]
    job, axis, script, said = jogger([*keys, (last + 5.0, QUIT)])
    assert job.run() == "quit"
    jogs = [c for c in axis.calls if c[1] == "jog"]
    stops = [c for c in axis.calls if c[1] == "stop"]
    assert jogs == [(1.0, "jog", SPEED)] and len(stops) == 1  # one lease, one stop
    assert last + RELEASE <= stops[0][0] <= last + RELEASE + 1e-9
    renewals = [t for t, what, _ in axis.calls if what == "renew"]
    gaps = [b - a for a, b in zip([1.0, *renewals], [*renewals, stops[0][0]], strict=True)]
    assert max(gaps) <= RENEW_S + 1e-9  # renewed through the repeat delay, no gap > RENEW_S
    assert said == ["jogging + at 20 mm/s", f"stopped: released ({RELEASE:g} s after the "
                                            "last key)"]
    assert all(w is None or w <= RENEW_S for w in script.waits)
    assert script.waits[0] is None and script.waits[-1] is None  # at rest: waits for a key


def test_the_other_direction_reverses_and_any_other_key_stops() -> None:
    job, axis, _, said = jogger([(0.0, PLUS), (0.1, PLUS), (0.2, MINUS), (0.3, OTHER),
                                 (0.4, MINUS), (0.5, QUIT)])
    assert job.run() == "quit"
    assert [(what, v) for _, what, v in axis.calls if what != "renew"] == [
        ("jog", SPEED), ("jog", -SPEED), ("stop", 0.0), ("jog", -SPEED), ("stop", 0.0)]
    assert said[2] == "stopped: another key" and said[-1] == "stopped: quit"
    assert job.starts == 3


def test_at_the_soft_limit_the_jog_says_so_and_takes_the_other_way() -> None:
    job, axis, _, said = jogger([(0.0, PLUS), (0.1, MINUS), (0.2, QUIT)])
    axis.refuse = 1.0
    assert job.run() == "quit"
    assert "at soft limit 300 mm" in said[0] and said[1] == "jogging - at 20 mm/s"
    assert [what for _, what, _ in axis.calls] == ["jog", "stop"]


def test_a_lease_that_ended_underneath_ends_the_command() -> None:
    job, axis, _, _ = jogger([(0.0, PLUS), (0.1, PLUS)])
    axis.renewals_end = True
    with pytest.raises(CliError, match="the jog ended"):
        job.run()


# ------------------------------------------------------------------ the command


@pytest.fixture
def terminal(monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """A pseudo-terminal as standard input; yields the master side (what the keyboard
    writes to)."""
    master, slave = pty.openpty()
    stdin = os.fdopen(slave, "r")
    monkeypatch.setattr(sys, "stdin", stdin)
    yield master
    stdin.close()
    os.close(master)


def test_jog_on_a_terminal_moves_and_restores_the_terminal(
        capsys: pytest.CaptureFixture[str], terminal: int) -> None:
    slave = sys.stdin.fileno()
    before = termios.tcgetattr(slave)

    def keyboard() -> None:  # once jog has the terminal in cbreak mode: a key, then q
        wait_until(lambda: not termios.tcgetattr(slave)[3] & termios.ICANON,
                   what="the terminal in cbreak mode")
        os.write(terminal, b"\x1b[C\x1b[C\x1b[Cq")

    typist = threading.Thread(target=keyboard, daemon=True)
    typist.start()
    code, out, err = run(capsys, "--axis", "x", "--json", "jog", "--speed", str(SPEED))
    typist.join(5)
    assert code == 0, err
    doc = json.loads(out)
    assert (doc["axis"], doc["jogs"], doc["ended"], doc["unit"]) == ("x", 1, "quit", "mm")
    assert "jog x at 20 mm/s: hold Right/Up or Left/Down" in err
    assert "jogging + at 20 mm/s" in err and "stopped: quit" in err
    assert termios.tcgetattr(slave) == before


class Interrupting:
    """A key source: one arrow, then Ctrl-C."""

    def __init__(self) -> None:
        self.keys = [PLUS]

    def __enter__(self) -> Interrupting:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        return None

    def read(self, timeout: float | None) -> str | None:
        if self.keys:
            return self.keys.pop()
        raise KeyboardInterrupt


def test_ctrl_c_stops_the_jog_and_exits_130(capsys: pytest.CaptureFixture[str],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jog_cmd, "terminal_keys", Interrupting)
    code, out, err = run(capsys, "--url", "sim://easycan?fast=1", "jog", "--speed", "30")
    assert code == F.EXIT_INTERRUPTED and out == ""
    assert "jog the drive at 30 rpm" in err and "jogging + at 30 rpm" in err
    assert "motion stopped" in err


def test_jog_needs_a_terminal(capsys: pytest.CaptureFixture[str],
                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "stdin", io.StringIO("\x1b[Cq"))  # a pipe, not a terminal
    code, out, err = run(capsys, "--axis", "x", "jog")
    assert code == F.EXIT_USAGE and out == "" and "arrow keys of a terminal" in err


def test_a_machine_axis_without_a_speed_needs_speed(capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    tmp_path: Path) -> None:
    monkeypatch.setattr(jog_cmd, "terminal_keys", Interrupting)
    path = tmp_path / "m.toml"
    path.write_text('[axes.r]\nurl = "sim://dyn232?fast=1"\nunit = "rev"\n', encoding="utf-8")
    code, out, err = run(capsys, "--machine", str(path), "jog")
    assert code == F.EXIT_USAGE and out == ""
    assert "gives axis r no speed: give --speed in rev/s" in err
