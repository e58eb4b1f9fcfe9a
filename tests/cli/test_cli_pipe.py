"""A closed standard output ends a command quietly (issue 17.8).

``servobus profile ... | head -3``: the reader is gone before the command has written
everything. The test makes that deterministic: the pipe's reading end is closed before the
command starts, so its first write fails.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import pytest

pytestmark = pytest.mark.timeout(60)
PROFILE = [sys.executable, "-m", "servobus", "profile", "--max-speed", "48", "--max-accel",
           "30", "--gear", "4096", "140000"]


@pytest.mark.parametrize("json_option", [[], ["--json"]], ids=["table", "json"])
def test_a_closed_stdout_ends_quietly_with_exit_0(json_option: list[str]) -> None:
    read_end, write_end = os.pipe()
    os.close(read_end)  # `| head -3` after it read its lines
    try:
        r = subprocess.run([*PROFILE, *json_option], stdout=write_end, stderr=subprocess.PIPE,
                           text=True, timeout=30)
    finally:
        os.close(write_end)
    assert r.returncode == 0 and r.stderr == ""


def test_an_open_stdout_still_gets_the_table() -> None:
    r = subprocess.run(PROFILE, capture_output=True, text=True, timeout=30)
    assert r.returncode == 0 and "Maximum motor speed" in r.stdout


def test_only_a_pipe_without_reader_counts_as_closed(monkeypatch: pytest.MonkeyPatch) -> None:
    from servobus.cli.main import stdout_closed

    read_end, write_end = os.pipe()
    with os.fdopen(write_end, "w") as pipe:
        monkeypatch.setattr(sys, "stdout", pipe)
        assert not stdout_closed()  # a reader is there
        os.close(read_end)
        assert stdout_closed()
    with tempfile.TemporaryFile("w") as file:
        monkeypatch.setattr(sys, "stdout", file)
        assert not stdout_closed()
