"""The EtherNet/IP commands through ``python -m servobus``: ``sim enip`` serving two drives on
127.0.0.1/127.0.0.2, ``discover``, ``io``, and the drive commands with ``--url enip://``."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
SAFETY_NET_S = "600"  # --duration: the fixture stops it; a loaded module takes minutes
LISTENING = re.compile(r"listening on enip://([\d.]+):(\d+) \(UDP ListIdentity (\d+), "
                       r"Class 1 I/O (\d+)\)")


def servobus(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "servobus", *args], capture_output=True,
                          text=True, timeout=timeout, check=False)


@pytest.fixture(scope="module")
def adapters() -> Iterator[list[tuple[str, int, int]]]:
    """``servobus sim enip`` on two loopback addresses: (host, TCP port, UDP list port)."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "enip", "--listen",
                             "127.0.0.1,127.0.0.2", "--tcp-port", "0", "--udp-port", "0",
                             "--duration", SAFETY_NET_S], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    found = []
    for _ in range(2):
        line = proc.stdout.readline()
        match = LISTENING.match(line)
        assert match, line
        found.append((match.group(1), int(match.group(2)), int(match.group(3))))
    yield found
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=10)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "stopped" in err


def test_both_drives_listen_on_one_port(adapters: list[tuple[str, int, int]]) -> None:
    assert [h for h, _, _ in adapters] == ["127.0.0.1", "127.0.0.2"]
    assert adapters[0][1] == adapters[1][1] > 0  # the same TCP port, as real drives


def test_discover_lists_the_given_addresses(adapters: list[tuple[str, int, int]]) -> None:
    port = adapters[0][2]
    done = servobus("discover", "127.0.0.1,127.0.0.2", "127.0.0.3", "--port", str(port),
                    "--timeout", "0.5")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split()[0] for line in lines] == [f"127.0.0.1:{port}", f"127.0.0.2:{port}"]
    assert all("DYN5ENIP" in line and "vendor 0xABCD" in line for line in lines)
    as_json = servobus("--json", "discover", "127.0.0.2", "--port", str(port))
    [record] = json.loads(as_json.stdout)
    assert record["address"] == "127.0.0.2" and record["serial_number"] == "00000001"


def test_discover_with_nobody_there_says_so() -> None:
    done = servobus("discover", "127.0.0.1", "--port", "9", "--timeout", "0.2")
    assert done.returncode == 0 and done.stdout == ""
    assert "no EtherNet/IP adapter answered" in done.stderr


def test_io_shows_input_frames(adapters: list[tuple[str, int, int]]) -> None:
    host, port, _ = adapters[0]
    done = servobus("--url", f"enip://{host}:{port}", "io", "--rpi", "10", "--count", "5")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 5 and all(line.startswith("seq") for line in lines)
    assert "(enabled, in position)" in lines[0]
    assert "frames 5" in done.stderr and "losses 0" in done.stderr
    as_json = servobus("--url", f"enip://{host}:{port}", "--json", "io", "--count", "3")
    records = [json.loads(line) for line in as_json.stdout.splitlines()]
    assert [r["sequence"] for r in records] == [1, 2, 3]


def test_io_refuses_a_too_short_rpi_and_other_protocols() -> None:
    assert servobus("--url", "enip://127.0.0.1:1", "io", "--rpi", "4").returncode == 2
    other = servobus("--url", "sim://dyn232?fast=1", "io", "--count", "1")
    assert other.returncode == 2 and "no cyclic I/O" in other.stderr


def test_drive_commands_over_enip(adapters: list[tuple[str, int, int]]) -> None:
    host, port, _ = adapters[0]
    url = f"enip://{host}:{port}"
    status = servobus("--url", url, "--json", "status")
    record = json.loads(status.stdout)
    assert record["protocol"] == "enip" and record["family"] == "dmm-dyn5"
    assert record["vendor_status"]["servo_free"] is False
    assert servobus("--url", url, "--id", "2", "set", "memory_test", "7").returncode == 0
    params = json.loads(servobus("--url", url, "--id", "2", "--json", "params").stdout)
    assert params["params"]["memory_test"] == 7
    assert json.loads(servobus("--url", url, "--json", "params").stdout)["params"][
        "memory_test"] == 0
    moved = servobus("--url", url, "move", "0.5rev", "--wait")
    assert moved.returncode == 0 and "done at" in moved.stdout
    scan = servobus("--url", url, "scan", "--last", "4")
    assert "found 2 drive(s)" in scan.stdout and scan.stdout.rstrip().endswith("1 2")
    refused = servobus("--url", url, "set", "memory_test", "64")
    assert refused.returncode == 2 and "0..63" in refused.stderr
    absent = servobus("--url", f"enip://127.0.0.1:{port}", "--id", "9", "status")
    assert absent.returncode == 2 and "127.0.0.9" in absent.stderr


def test_sim_enip_refuses_bad_addresses() -> None:
    done = servobus("sim", "enip", "--listen", "localhost", "--duration", "0")
    assert done.returncode == 2 and "IPv4" in done.stderr


def test_io_ends_normally_on_sigterm(adapters: list[tuple[str, int, int]]) -> None:
    host, port, _ = adapters[1]
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "--url",
                             f"enip://{host}:{port}", "io"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    try:
        assert proc.stdout.readline().startswith("seq")  # watching
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    finally:
        proc.kill()
    assert proc.returncode == 0 and "stopped by SIGTERM" in err
    again = servobus("--url", f"enip://{host}:{port}", "io", "--count", "1")
    assert again.returncode == 0, again.stderr  # the drive takes a new owner
