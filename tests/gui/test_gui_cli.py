"""``servobus gui`` as a user runs it: address, token, warnings, drives, exit."""

from __future__ import annotations

import json
import queue
import re
import signal
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from rig import wait_until
from subprocess_rig import read_line, stop_process

from servobus.axis import connect

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow]


_readers: dict[int, threading.Thread] = {}


@contextmanager
def gui(*args: str) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    """Start ``servobus gui ... --port 0 --no-browser``; yield once it printed its URL.

    The list keeps growing with what the process prints later (a reader thread)."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "gui", "--port", "0",
                             "--no-browser", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    lines: queue.Queue[str] = queue.Queue()
    seen: list[str] = []

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            seen.append(line)
            lines.put(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    _readers[proc.pid] = reader
    try:
        while not any("drives:" in line for line in seen):
            try:
                lines.get(timeout=20)
            except queue.Empty:
                proc.kill()
                pytest.fail(f"gui did not start: {seen}")
        yield proc, seen
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def ended(proc: subprocess.Popen[str]) -> str:
    """Wait for the end of ``proc``; its stderr (stdout belongs to the reader thread)."""
    proc.wait(timeout=20)
    _readers[proc.pid].join(timeout=10)  # every line it printed is in the list
    assert proc.stderr is not None
    return proc.stderr.read()


def get(url: str) -> tuple[int, object]:
    try:
        with urllib.request.urlopen(url, timeout=5) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def test_default_serves_the_builtin_machine_on_loopback_and_stops_on_ctrl_c() -> None:
    with gui() as (proc, lines):
        assert len(lines) == 2  # no warning on loopback
        url = re.search(r"http://127\.0\.0\.1:\d+/", lines[0])
        assert url is not None and "token" not in lines[0]
        # issue 20: with nothing named, the built-in virtual machine (x, y DMM; c YZ-AIM)
        assert "built-in virtual machine" in lines[1] and "axes 1 x, 2 y, 3 c" in lines[1]
        status, info = get(url.group(0) + "api/info")
        assert status == 200 and [a["id"] for a in info["axes"]] == [1, 2, 3]  # type: ignore[index]
        proc.send_signal(signal.SIGINT)
        err = ended(proc)
    # Ctrl-C is how a server ends: exit 0, no error line (issue 17.8, docs/gui.md)
    assert proc.returncode == 0 and err == ""
    assert lines[-1].strip() == ("servobus gui: Ctrl-C: every axis was stopped and the GUI "
                                 "server closed")


def test_beyond_loopback_a_token_is_generated_and_required_with_a_warning() -> None:
    with gui("--host", "0.0.0.0", "--url", "sim://dyncan?fast=1", "--ids", "1,2") as (_, lines):
        assert lines[0].startswith("warning: listening on 0.0.0.0")
        assert "move the drives" in lines[0]
        m = re.search(r"(http://127\.0\.0\.1:\d+/)\?token=([\w-]{20,})", lines[1])
        assert m is not None, lines
        base, token = m.groups()
        assert "axes 1, 2" in lines[2] and "sim://dyncan" in lines[2]
        assert get(base + "api/info")[0] == 401
        status, info = get(f"{base}api/info?token={token}")
        assert status == 200
        assert {a["protocol"] for a in info["axes"]} == {"dyncan"}  # type: ignore[index]


@pytest.mark.parametrize("args,text", [
    (["--id", "1", "--ids", "1,2"], "--id or --ids"),
    (["--ids", "1,x"], "drive ids"),
    (["--url", "nosuch://x"], "nosuch"),
    (["--host", "127.0.0.1", "--token", " "], "token"),
])
def test_usage_and_connection_errors_are_one_line_exit_2(args: list[str], text: str) -> None:
    r = subprocess.run([sys.executable, "-m", "servobus", "gui", "--port", "0",
                        "--no-browser", *args], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2, r
    assert text in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_help_names_every_option() -> None:
    r = subprocess.run([sys.executable, "-m", "servobus", "gui", "--help"],
                       capture_output=True, text=True, timeout=30)
    for option in ("--url", "--id", "--ids", "--host", "--port", "--no-browser", "--token"):
        assert option in r.stdout


@pytest.fixture
def line_url() -> Iterator[str]:
    """A virtual DYN232M line (drive 1) on a free port, outside the GUI's process; it stops
    by itself after 60 s at the latest."""
    sim = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "dyn232", "--fast",
                            "--ids", "1", "--listen", "tcp://127.0.0.1:0", "--duration", "60"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = read_line(sim, "listening on tcp://")
        yield "socket://" + line.split("tcp://", 1)[1].split()[0]
    finally:
        stop_process(sim)


def post(url: str, doc: object) -> int:
    request = urllib.request.Request(url, json.dumps(doc).encode(), method="POST",
                                      headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=5) as r:
        return int(r.status)


@pytest.mark.parametrize("sig,times", [(signal.SIGINT, 1), (signal.SIGTERM, 1),
                                       (signal.SIGINT, 2)],
                         ids=["SIGINT", "SIGTERM", "SIGINT-twice"])
def test_a_signal_stops_the_turning_axis_and_ends_the_gui_normally(
        line_url: str, sig: signal.Signals, times: int) -> None:
    """A second Ctrl-C makes uvicorn skip the app's shutdown: every axis still stops."""
    with gui("--url", "dyn232+" + line_url, "--id", "1") as (proc, lines), \
            connect("dyn232+" + line_url, drive_id=1) as watcher:
        base = re.search(r"http://127\.0\.0\.1:\d+/", lines[0])
        assert base is not None
        start = watcher.position()

        def turning() -> bool:  # constant speed is a lease: this client renews it (issue 27)
            assert post(base.group(0) + "api/axes/1/turn", {"rpm": 300, "ttl": 1.0}) == 200
            return abs(watcher.position() - start) > 65536

        wait_until(turning, timeout=10, what="turning at 300 rpm")
        assert post(base.group(0) + "api/axes/1/turn", {"rpm": 300, "ttl": 1.0}) == 200
        for _ in range(times):
            proc.send_signal(sig)
        err = ended(proc)
        # the stop ramps down at Max Accel: at standstill well within a second
        wait_until(lambda: watcher.speed() == 0, timeout=3, what="axis 1 at standstill")
    name = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
    assert proc.returncode == 0 and err == ""
    assert lines[-1].startswith(f"servobus gui: {name}: every axis was stopped")
