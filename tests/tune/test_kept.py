"""The kept-gains record of a tuning run (servobus.tune.kept): who counts as still tuning,
what an interrupted run refuses, a damaged record, and no record for in-process drives."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from servobus.errors import OwnerError, ServobusError, TuningInterrupted
from servobus.tune import kept

URL = "dyn232+socket://127.0.0.1:5000"
GAINS = {"main_gain": 40, "speed_gain": 40}


@pytest.fixture(autouse=True)
def state(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    return tmp_path / "servobus" / "tune"


def record() -> kept.Record:
    found = kept.record_for(URL, 1, "axis x")
    assert found is not None
    return found


def test_in_process_virtual_drives_are_not_recorded_and_drives_are_told_apart() -> None:
    assert kept.record_for("sim://dyn232?fast=1", 1, "axis x") is None
    assert kept.record_for(" SIM://easycan", 1, "axis x") is None
    paths = {r.path for r in (record(), kept.record_for(URL, 2, "y"),
                              kept.record_for(URL + "1", 1, "z")) if r is not None}
    assert len(paths) == 3


def test_a_run_of_this_process_is_alive_and_a_second_record_is_refused(state: Path) -> None:
    first = record()
    first.check_free()  # nothing recorded yet
    first.write(GAINS)
    assert first.path.parent == state and first.path.stat().st_mode & 0o777 == 0o600
    with pytest.raises(OwnerError, match="being tuned by process"):
        record().check_free()
    with pytest.raises(OwnerError, match="first; one run at a time"):
        record().write(GAINS)  # the exclusive create: no two runs on one drive
    with pytest.raises(OwnerError, match="stop that run"):
        record().take()
    record().remove()  # not ours: stays
    assert first.path.exists()
    first.remove()
    assert not first.path.exists()


def ended_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_record_whose_process_is_gone_refuses_the_next_run_until_restore() -> None:
    r = record()
    r.write(GAINS)
    doc = json.loads(r.path.read_text())
    doc["pid"] = ended_pid()
    r.path.write_text(json.dumps(doc))
    with pytest.raises(TuningInterrupted, match="--restore") as info:
        record().check_free()
    assert info.value.path == r.path and "main_gain" in str(info.value)
    assert record().take() == GAINS
    record().drop()
    with pytest.raises(ServobusError, match="nothing to restore"):
        record().take()


def test_a_reused_pid_is_not_taken_for_the_run() -> None:
    r = record()
    r.write(GAINS)
    doc = json.loads(r.path.read_text())
    assert doc["started"] is None or doc["started"].isdigit()
    if doc["started"] is None:
        pytest.skip("no /proc here: a process's start time is not known")
    doc["started"] = str(int(doc["started"]) + 1)  # this pid, another process start
    r.path.write_text(json.dumps(doc))
    with pytest.raises(TuningInterrupted):
        record().check_free()


def test_another_hosts_record_counts_as_running_but_restore_takes_it() -> None:
    r = record()
    r.write(GAINS)
    doc = json.loads(r.path.read_text())
    doc["host"] = socket.gethostname() + "-other"
    doc["pid"] = ended_pid()
    r.path.write_text(json.dumps(doc))
    with pytest.raises(OwnerError, match="-other"):
        record().check_free()
    assert record().take() == GAINS


@pytest.mark.parametrize("text", ["{", "[]", '{"gains": {"main_gain": 1.5}}',
                                  '{"gains": {"main_gain": true}}', '{"pid": 1}'])
def test_a_damaged_record_is_said_and_left_alone(text: str, state: Path) -> None:
    r = record()
    state.mkdir(parents=True)
    r.path.write_text(text)
    with pytest.raises(ServobusError, match="damaged"):
        record().check_free()
    with pytest.raises(ServobusError, match="damaged"):
        record().take()
    assert r.path.read_text() == text


def test_a_folder_that_cannot_be_written_refuses_the_run(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("XDG_STATE_HOME", str(blocker))  # a file where the folder would be
    with pytest.raises(ServobusError, match="cannot record") as info:
        record().write(GAINS)
    assert not isinstance(info.value, OwnerError)
    assert os.path.isfile(blocker)
