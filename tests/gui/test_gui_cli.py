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

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow]


@contextmanager
def gui(*args: str) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    """Start ``servobus gui ... --port 0 --no-browser``; yield once it printed its URL."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "gui", "--port", "0",
                             "--no-browser", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    lines: queue.Queue[str] = queue.Queue()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)

    threading.Thread(target=read, daemon=True).start()
    seen: list[str] = []
    try:
        while not any("drives:" in line for line in seen):
            try:
                seen.append(lines.get(timeout=20))
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


def get(url: str) -> tuple[int, object]:
    try:
        with urllib.request.urlopen(url, timeout=5) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def test_default_serves_three_virtual_axes_on_loopback_and_stops_on_ctrl_c() -> None:
    with gui() as (proc, lines):
        assert len(lines) == 2  # no warning on loopback
        url = re.search(r"http://127\.0\.0\.1:\d+/", lines[0])
        assert url is not None and "token" not in lines[0]
        assert "built-in virtual drives" in lines[1] and "axes 1, 2, 3" in lines[1]
        status, info = get(url.group(0) + "api/info")
        assert status == 200 and [a["id"] for a in info["axes"]] == [1, 2, 3]  # type: ignore[index]
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
    assert proc.returncode == 130
    assert err.strip() == ("error: interrupted by Ctrl-C - every axis was stopped and the GUI "
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
