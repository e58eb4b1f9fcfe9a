"""The servobus command on a YZ-AIM motor over Modbus RTU: ``servobus sim modbus`` in its own
process, every drive command through ``--url modbus+socket://...``, decode and sniff."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]
SAFETY_NET_S = "600"  # --duration: the fixture stops it; a loaded module takes minutes


def servobus(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    # Reads get a roomy 2 s deadline unless the test sets one: the default (three attempts
    # of ~60 ms at 19200 baud) ran out beside two CPU hogs; deadlines are tested elsewhere.
    roomy = () if "--timeout" in args else ("--timeout", "2")
    return subprocess.run([sys.executable, "-m", "servobus", *roomy, *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def line() -> Iterator[tuple[str, str]]:
    """(drive URL, tap URL) of a virtual line with motors 1 and 2, unpaced."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "modbus", "--fast",
                             "--ids", "1,2", "--listen", "tcp://127.0.0.1:0",
                             "--tap", "tcp://127.0.0.1:0", "--duration", SAFETY_NET_S],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        listen = proc.stdout.readline().strip()
        tap = proc.stdout.readline().strip()
        assert listen.startswith("listening on tcp://") and tap.startswith("tap on tcp://")
        url = "modbus+socket://" + listen.split("tcp://", 1)[1]
        yield url, "tcp://" + tap.split("tcp://", 1)[1]
    finally:
        proc.terminate()
        proc.wait(10)


def test_status_position_and_a_move_in_counts(line: tuple[str, str]) -> None:
    url, _ = line
    out = servobus("--url", url, "--id", "2", "status", "--json")
    assert out.returncode == 0, out.stderr
    status = json.loads(out.stdout)
    assert status["family"] == "yzaim" and status["enabled"] and status["alarm_code"] == 0
    move = servobus("--url", url, "--id", "2", "move", "--wait", "0.25rev")
    assert move.returncode == 0, move.stderr
    out = servobus("--url", url, "--id", "2", "position", "--json")
    assert abs(json.loads(out.stdout)["position"] - 8192) <= 10, out.stdout


def test_speed_stop_params_set_and_backup(line: tuple[str, str], tmp_path: Path) -> None:
    url, _ = line
    # issue 27: speed holds the motion while it runs; --for ends it (then it stops)
    assert servobus("--url", url, "--id", "1", "speed", "200", "--for", "0.3").returncode == 0
    assert servobus("--url", url, "--id", "1", "stop").returncode == 0
    out = servobus("--url", url, "--id", "1", "set", "acceleration", "20000")
    assert out.returncode == 0, out.stderr
    bad = servobus("--url", url, "--id", "1", "set", "acceleration", "70000")
    assert bad.returncode == 2 and "acceleration" in bad.stderr
    backup = tmp_path / "yzaim.json"
    out = servobus("--url", url, "--id", "1", "params", "--save", str(backup))
    assert out.returncode == 0, out.stderr
    saved = json.loads(backup.read_text())
    assert saved["params"]["acceleration"] == 20000
    assert servobus("--url", url, "--id", "1", "params", "--diff", str(backup)).returncode == 0


def test_scan_finds_both_motors(line: tuple[str, str]) -> None:
    url, _ = line
    out = servobus("--url", url, "scan", "--first", "1", "--last", "4", "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == [1, 2]


def test_an_absent_motor_is_a_connection_problem(line: tuple[str, str]) -> None:
    url, _ = line
    out = servobus("--url", url, "--id", "9", "--timeout", "0.05", "position")
    assert out.returncode == 2 and "error:" in out.stderr


def test_decode_names_the_registers() -> None:
    out = servobus("decode", "--protocol", "modbus", "01 03 00 0e 00 01 e5 c9",
                   "01 03 02 00 14 b8 4b")
    assert out.returncode == 0, out.stderr
    assert "id 1 read 0x000E alarm_code" in out.stdout
    assert "id 1 read reply [20]" in out.stdout
    bad = servobus("decode", "--protocol", "modbus", "01 03 00 0e 00 01 e5 c8")
    assert bad.returncode == 1 and "dropped" in bad.stdout


def test_sniff_the_tap(line: tuple[str, str]) -> None:
    url, tap = line
    sniff = subprocess.Popen([sys.executable, "-m", "servobus", "--json", "sniff", "--tap",
                              tap, "--protocol", "modbus", "--count", "2"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(20):  # until the tap client is connected and sees the traffic
            servobus("--url", url, "--id", "1", "position")
            if sniff.poll() is not None:
                break
        out, err = sniff.communicate(timeout=30)
    finally:
        if sniff.poll() is None:
            sniff.kill()
    records = [json.loads(line) for line in out.splitlines()]
    assert len(records) >= 2, err
    assert records[0]["direction"] == "host->drive" and "read 0x0016" in records[0]["text"]
    assert records[1]["direction"] == "drive->host"


def test_sim_modbus_in_process_from_the_cli() -> None:
    out = servobus("--url", "sim://modbus?fast=1", "--id", "3", "status", "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["family"] == "yzaim"
