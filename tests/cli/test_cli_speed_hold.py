"""``servobus speed`` holds its motion (issue 27): a lease the CLI process renews.

In-process: ``--for`` streams targets, then stops; on a ``continuous`` axis the speed is
open-ended and the command returns at once. With real processes: a virtual DYN CAN drive
in its own process (socketcand), ``servobus speed`` (or ``servobus jog`` on a pseudo-terminal,
its key held) in another, SIGKILLed while the motor cruises; a third client watches the drive
come to rest within the documented bound (docs/safety.md: the lead of the last renewal plus
one renewal period's travel).
"""

from __future__ import annotations

import contextlib
import json
import os
import pty
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from rig import wait_until
from subprocess_rig import read_line, stop_process

import servobus.machine.links as links
from servobus.axis import connect
from servobus.axis.base import AsyncAxis
from servobus.cli.main import main
from servobus.machine.lease import STREAM_S, lead

SERVOBUS = [sys.executable, "-m", "servobus"]
RPM = 600


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as info:
        main(list(args))
    out, err = capsys.readouterr()
    return int(info.value.code or 0), out, err


@pytest.fixture
def calls(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The motion primitives every Axis the CLI opens is asked for, in order."""
    seen: list[str] = []
    real = links.connect_async

    async def counted(url: str | None = None, **kw: Any) -> AsyncAxis:
        axis = await real(url, **kw)
        for name in ("stream_to", "turn", "stop"):
            method = getattr(axis, name)

            async def wrapper(*args: Any, _name: str = name, _method: Any = method) -> Any:
                seen.append(_name)
                return await _method(*args)

            setattr(axis, name, wrapper)
        return axis

    monkeypatch.setattr(links, "connect_async", counted)
    return seen


def test_for_streams_targets_then_stops(capsys: pytest.CaptureFixture[str],
                                        calls: list[str]) -> None:
    code, out, err = run(capsys, "--url", "sim://dyn232?fast=1", "--json", "speed", "--for",
                         "0.3", str(RPM))
    assert code == 0, err
    doc = json.loads(out)
    assert (doc["speed_command"], doc["ended"]) == (RPM, "for") and doc["held_s"] >= 0.3
    assert "turning at 600 rpm while this command runs" in err
    stop = calls.index("stop")  # stop() is turn(0) underneath: nothing turns before it
    assert calls[:stop].count("stream_to") >= 2 and "turn" not in calls[:stop]  # a lease
    assert "stream_to" not in calls[stop:]  # no target update follows the stop


def test_a_continuous_axis_returns_at_once_open_ended(capsys: pytest.CaptureFixture[str],
                                                      calls: list[str]) -> None:
    code, out, err = run(capsys, "--url", "sim://dyn232?fast=1&continuous=1", "--json",
                         "speed", str(RPM))
    assert code == 0, err
    assert json.loads(out) == {"speed_command": RPM, "ended": "continuous"}
    assert calls == ["turn"]  # one open-ended speed command; nothing stops it
    code, out, _ = run(capsys, "--url", "sim://dyn232?fast=1&continuous=1", "speed", str(RPM))
    assert "continuous: open-ended, `servobus stop` stops it" in out


def test_a_speed_above_the_profile_is_refused_in_rpm(capsys: pytest.CaptureFixture[str],
                                                     calls: list[str]) -> None:
    code, _, err = run(capsys, "--url", "sim://dyncan?fast=1", "speed", "5000")
    assert code == 2 and "speed 5000 rpm is outside the -" in err and "max_speed" in err
    assert calls == []


# ------------------------------------------------------------------ the owner dies
#: The virtual drive in its own process, per protocol: the command line, what it prints when
#: it listens, and the URL that reaches it (docs/safety.md: the front ends' kill tests cover
#: every protocol between them; the CLI's covers DYN CAN and Modbus RTU).
DRIVES = {
    "dyncan": (["dyncan", "--socketcand", "127.0.0.1:0"], "listening on socketcand ",
               "dyncan+socketcand://"),
    "modbus": (["modbus", "--listen", "tcp://127.0.0.1:0"], "listening on ",
               "modbus+socket://"),
}


@pytest.fixture(params=sorted(DRIVES))
def drive_url(request: pytest.FixtureRequest) -> Iterator[str]:
    """A virtual drive (id 1) in its own process; stops by itself at the latest after
    --duration (a safety net: the fixture stops it)."""
    args, listening, scheme = DRIVES[request.param]
    sim = subprocess.Popen([*SERVOBUS, "sim", *args, "--fast", "--ids", "1",
                            "--duration", "300"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = read_line(sim, listening)
        address = line.rsplit(" ", 1)[1]
        yield scheme + address.removeprefix("tcp://")
    finally:
        stop_process(sim)


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_a_killed_speed_command_stops_within_the_lead(drive_url: str) -> None:
    url = drive_url
    with connect(url, drive_id=1) as watcher:
        cpr = watcher.counts_per_rev
        profile = watcher.stream_profile()
        start = watcher.position()
        cli = subprocess.Popen([*SERVOBUS, "--url", url, "--id", "1", "speed", str(RPM)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            def cruising() -> bool:
                assert cli.poll() is None, cli.communicate()
                return watcher.position() - start > 2 * cpr  # 0.2 s at 600 rpm
            wait_until(cruising, timeout=30, what="the held speed to move the motor 2 rev")
            cli.send_signal(signal.SIGKILL)
            cli.wait(10)
            at_death = watcher.position()
        finally:
            stop_process(cli)
        samples: list[int] = []

        def at_rest() -> bool:
            samples.append(watcher.position())
            return len(samples) > 3 and len(set(samples[-3:])) == 1 \
                and not watcher.status().moving
        wait_until(at_rest, timeout=30, poll=0.1, what="the motor at rest after the owner died")
        travel = samples[-1] - at_death
    v = RPM * cpr / 60  # counts/s
    bound = lead(v, profile.accel_rpm_s * cpr / 60) + v * STREAM_S
    # at_death is read after the kill, so the travel from it is at most the last lead;
    # the bound adds one renewal period (docs/safety.md) and the margin 1/16 rev for the
    # drive's settling. A lease left streaming or an open-ended speed would run on for ever.
    assert -cpr / 16 <= travel <= bound + cpr / 16, (travel, bound)


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_a_killed_jog_stops_within_the_lead(drive_url: str) -> None:
    """``servobus jog`` on a terminal, its arrow key held (auto-repeat), SIGKILLed while the
    motor cruises: the drive comes to rest by itself within the same bound as ``speed``."""
    url = drive_url
    master, slave = pty.openpty()
    with connect(url, drive_id=1) as watcher:
        cpr = watcher.counts_per_rev
        profile = watcher.stream_profile()
        start = watcher.position()
        cli = subprocess.Popen([*SERVOBUS, "--url", url, "--id", "1", "jog", "--speed",
                                str(RPM)], stdin=slave, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        held = threading.Event()

        def keyboard() -> None:  # a held Right key: the terminal's auto-repeat
            while not held.wait(0.03):
                with contextlib.suppress(OSError):
                    os.write(master, b"\x1b[C")

        typist = threading.Thread(target=keyboard, daemon=True)
        typist.start()
        try:
            def cruising() -> bool:
                assert cli.poll() is None, cli.communicate()
                return watcher.position() - start > 2 * cpr  # 0.2 s at 600 rpm
            wait_until(cruising, timeout=30, what="the jog to move the motor 2 rev")
            cli.send_signal(signal.SIGKILL)
            cli.wait(10)
            at_death = watcher.position()
        finally:
            held.set()
            typist.join(5)
            stop_process(cli)
            os.close(master)
            os.close(slave)
        samples: list[int] = []

        def at_rest() -> bool:
            samples.append(watcher.position())
            return len(samples) > 3 and len(set(samples[-3:])) == 1 \
                and not watcher.status().moving
        wait_until(at_rest, timeout=30, poll=0.1, what="the motor at rest after the jog died")
        travel = samples[-1] - at_death
    v = RPM * cpr / 60  # counts/s
    bound = lead(v, profile.accel_rpm_s * cpr / 60) + v * STREAM_S
    assert -cpr / 16 <= travel <= bound + cpr / 16, (travel, bound)
