"""A stop leaves a YZ-AIM motor ready for the next move, whichever program stopped it
(issue 28): ``servobus stop`` and Ctrl-C during ``move --wait`` in one process, the next
``move --wait`` in another, on EasyCan and on Modbus; and ``servobus set`` refuses a
speed-mode register write on an axis that is not continuous.

Real processes: ``servobus sim easycan`` / ``sim modbus`` serve the motor; each CLI command
is its own process, as a user runs them; a watcher on the same bus or line reads what the
motor does.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest
from rig import wait_until
from subprocess_rig import read_line, stop_process

from servobus.axis import connect
from servobus.families.yzaim import registers as Y

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]  # real processes and motion

SERVOBUS = [sys.executable, "-m", "servobus"]
LONG = "200rev"  # 12 s at the 1000 rpm cruise speed: still moving when the stop comes
WINDOW = Y.POSITION_TOLERANCE_COUNTS


@pytest.fixture(params=["easycan", "modbus"])
def url(request: pytest.FixtureRequest) -> Iterator[str]:
    """A virtual YZ-AIM motor 1 in its own process on a free port; a minute at most."""
    if request.param == "easycan":
        args = ["easycan", "--socketcand", "127.0.0.1:0"]
    else:
        args = ["modbus", "--listen", "tcp://127.0.0.1:0", "--fast"]
    sim = subprocess.Popen([*SERVOBUS, "sim", *args, "--ids", "1", "--duration", "90"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = read_line(sim, "listening on ")
        where = line.split()[-1].removeprefix("tcp://")
        yield (f"easycan+socketcand://{where}" if request.param == "easycan"
               else f"modbus+socket://{where}")
    finally:
        stop_process(sim)


def cli(url: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SERVOBUS, "--url", url, "--id", "1", *args],
                          capture_output=True, text=True, timeout=timeout)


def assert_next_move_arrives(url: str) -> None:
    """What used to hang ("still moving ..."): a move in a new process after the stop."""
    done = cli(url, "move", "--relative", "--wait", "--wait-timeout", "30", "1rev", "--json")
    assert done.returncode == 0, done.stderr
    record = json.loads(done.stdout)
    assert abs(record["position"] - record["target"]) <= WINDOW, record
    with connect(url, drive_id=1, timeout=2.0) as watcher:
        assert watcher.read_param("special_function") == Y.SpecialFunction.PULSE_DIRECTION
        assert watcher.read_param("target_speed") == 1000  # the cruise speed, not 0


def test_cli_stop_then_a_move_in_another_process_reaches_its_target(url: str) -> None:
    started = cli(url, "move", "--relative", LONG)
    assert started.returncode == 0, started.stderr
    with connect(url, drive_id=1, timeout=2.0) as watcher:
        wait_until(lambda: abs(watcher.speed()) > 500, timeout=20, what="the long move")
        stopped = cli(url, "stop")
        assert stopped.returncode == 0, stopped.stderr
        wait_until(lambda: watcher.speed() == 0, timeout=20, what="the motor at rest")
    assert_next_move_arrives(url)


def test_ctrl_c_during_move_wait_then_a_move_in_another_process(url: str) -> None:
    moving = subprocess.Popen([*SERVOBUS, "--url", url, "--id", "1", "move", "--relative",
                               "--wait", LONG], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    try:
        with connect(url, drive_id=1, timeout=2.0) as watcher:
            wait_until(lambda: abs(watcher.speed()) > 500, timeout=20, what="the long move")
            moving.send_signal(signal.SIGINT)
            _, err = moving.communicate(timeout=20)
            assert moving.returncode == 130, err
            wait_until(lambda: watcher.speed() == 0, timeout=20, what="the motor at rest")
    finally:
        if moving.poll() is None:
            moving.kill()
            moving.wait(5)
    assert_next_move_arrives(url)


def test_set_of_a_speed_mode_register_is_refused_unless_continuous(url: str) -> None:
    refused = cli(url, "set", "special_function", "3")
    assert refused.returncode == 2
    assert "not continuous" in refused.stderr and "nothing was written" in refused.stderr
    with connect(url, drive_id=1, timeout=2.0) as watcher:
        assert watcher.read_param("special_function") == 0
    allowed = cli(url + "?continuous=1", "set", "target_speed", "600")
    assert allowed.returncode == 0, allowed.stderr
