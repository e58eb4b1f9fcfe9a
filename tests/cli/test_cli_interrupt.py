"""Ctrl-C / SIGTERM during ``move --wait`` stops the motor; a simulator that dies is one line.

Real processes: ``servobus sim dyn232 --listen`` serves the line, the CLI moves drive 0, and a
second client on the same line watches what the drive does.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from servobus.axis import connect
from servobus.axis.sync import Axis
from servobus.cli.failures import EXIT_INTERRUPTED, EXIT_USAGE
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U

pytestmark = pytest.mark.slow  # real processes or seconds of wall-clock motion

SERVOBUS = [sys.executable, "-m", "servobus"]
LONG_MOVE = "10000000"  # command units: 40,000,000 counts, ~610 rev, ~18 s at the default speed
CRUISING_RPM = 500  # interrupt only once the motor is clearly moving


@pytest.fixture
def sim_url() -> Iterator[tuple[str, subprocess.Popen[str]]]:
    """A paced virtual line on a free port; stops by itself after 60 s at the latest."""
    sim = subprocess.Popen([*SERVOBUS, "sim", "dyn232", "--listen", "tcp://127.0.0.1:0",
                            "--duration", "60"], stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True)
    try:
        assert sim.stdout is not None
        line = sim.stdout.readline().strip()
        assert line.startswith("listening on tcp://"), line
        yield "socket://" + line.split("tcp://", 1)[1], sim
    finally:
        if sim.poll() is None:
            sim.terminate()
        sim.wait(10)


def start_move(url: str) -> subprocess.Popen[str]:
    return subprocess.Popen([*SERVOBUS, "--port", url, "move", "--relative", "--wait",
                             LONG_MOVE], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def wait_until_cruising(watcher: Axis, cli: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + 30
    while watcher.speed() < CRUISING_RPM:
        assert cli.poll() is None, cli.communicate()
        assert time.monotonic() < deadline, "the move never started"
        time.sleep(0.01)  # polling the drive's speed: no event reports it


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupt_during_move_wait_stops_the_drive(
        sim_url: tuple[str, subprocess.Popen[str]], sig: signal.Signals) -> None:
    url, _ = sim_url
    cli = start_move(url)
    try:
        with connect(url, timeout=2.0) as watcher:  # roomy: a loaded machine
            wait_until_cruising(watcher, cli)
            cli.send_signal(sig)
            _, err = cli.communicate(timeout=10)
            # Without the stop the drive would cruise for another ~17 s.
            deadline = time.monotonic() + 8  # generous; it takes ~0.1 s idle
            while (speed := watcher.speed()) != 0:
                assert time.monotonic() < deadline, f"still turning at {speed} rpm"
                time.sleep(0.01)  # polling the drive's speed: no event reports it
            held = [watcher.position() for _ in range(10)]  # ~10 polls on the paced line
            status = watcher.status()
    finally:
        if cli.poll() is None:
            cli.kill()
            cli.wait(5)
    assert cli.returncode == EXIT_INTERRUPTED
    name = "Ctrl-C" if sig is signal.SIGINT else "SIGTERM"
    assert err.splitlines() == [
        f"error: interrupted by {name} - motion stopped: the drive ramps down at Max Accel "
        "and holds position"]
    # Holding: the servo settles inside the OnRange window (turning at 500 rpm would cover
    # ~11,000 counts during these polls).
    assert max(held) - min(held) <= U.onrange_to_counts(P.spec("on_range").default), held
    assert not status.moving and status.enabled


def test_simulator_killed_during_move_wait_is_one_line(
        sim_url: tuple[str, subprocess.Popen[str]]) -> None:
    url, sim = sim_url
    cli = start_move(url)
    try:
        with connect(url, timeout=2.0) as watcher:  # roomy: a loaded machine
            wait_until_cruising(watcher, cli)
            sim.kill()
            sim.wait(10)
        _, err = cli.communicate(timeout=15)
    finally:
        if cli.poll() is None:
            cli.kill()
            cli.wait(5)
    assert cli.returncode == EXIT_USAGE
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("error: connection lost"), err
