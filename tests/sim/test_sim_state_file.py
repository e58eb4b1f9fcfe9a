"""The ``--state`` file (the virtual drives' EEPROM): refused when invalid, never
overwritten then, locked against a second simulator, written atomically (issue 8)."""

from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest
from sim_abuse_rig import SERVOBUS, readable, run_cli, sim

from servobus.families.dmm import params as P
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.sim.core.state_file import StateFile, StateFileError, parse_state
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.eeprom import DMM_STATE, EepromStore

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow]
H = c.HostFunction

GOOD = {"1": {"drive_id": 1, "params": {"main_gain": 55}}}
BAD_CONTENT: dict[str, tuple[bytes, str]] = {
    "empty": (b"", "is empty"),
    "blank": (b" \n", "is empty"),
    "truncated": (json.dumps(GOOD).encode()[:-7], "not valid JSON"),
    "binary": (bytes(range(256)), "not text"),
    "null": (b"null", "holds null"),
    "list": (b"[]", "holds a list"),
    "number": (b"42", "holds a int"),
    "float value": (b'{"1": {"drive_id": 1, "params": {"main_gain": 40.5}}}', "integer"),
    "string value": (b'{"1": {"drive_id": 1, "params": {"main_gain": "40"}}}', "integer"),
    "bool value": (b'{"1": {"drive_id": true}}', "integer"),
    "nan": (b'{"1": {"drive_id": 1, "origin": NaN}}', "not valid JSON"),
    "main_gain 9999": (b'{"1": {"drive_id": 1, "params": {"main_gain": 9999}}}',
                       "main_gain 9999 is outside 1..127"),
    "gear_num 99999": (b'{"1": {"drive_id": 1, "params": {"gear_num": 99999}}}',
                       "gear_num 99999 is outside 500..16384"),
    "unknown parameter": (b'{"1": {"drive_id": 1, "params": {"turbo": 1}}}',
                          "not an EEPROM parameter"),
    "no drive_id": (b'{"1": {"params": {"main_gain": 9}}}', "has no drive_id"),
    "drive_id 200": (b'{"1": {"drive_id": 200}}', "drive_id 200 is outside 0..63"),
    "drive_id -1": (b'{"1": {"drive_id": -1}}', "drive_id -1 is outside"),
    "key not an id": (b'{"one": {"drive_id": 1}}', "power-on drive id"),
    "key 64": (b'{"64": {"drive_id": 1}}', "power-on drive id"),
    "record not an object": (b'{"1": 5}', "must be an object"),
    "unknown field": (b'{"1": {"drive_id": 1, "colour": 3}}', "unknown field"),
    "config beyond its bits": (b'{"1": {"drive_id": 1, "config": 64}}', "config 64"),
    "origin beyond a turn": (b'{"1": {"drive_id": 1, "origin": 65536}}', "origin 65536"),
    "negative write count": (b'{"1": {"drive_id": 1, "writes": {"main_gain": -1}}}',
                             "outside"),
    "unknown write item": (b'{"1": {"drive_id": 1, "writes": {"x": 1}}}', "unknown item"),
}


@pytest.mark.parametrize("case", list(BAD_CONTENT))
def test_invalid_content_is_refused_with_the_file_named_and_left_unchanged(
        tmp_path: Path, case: str) -> None:
    raw, problem = BAD_CONTENT[case]
    path = tmp_path / "eeprom.json"
    path.write_bytes(raw)
    with pytest.raises(StateFileError) as err:
        EepromStore(path, key="1")
    message = str(err.value)
    assert str(path) in message and problem in message and "\n" not in message
    assert path.read_bytes() == raw
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eeprom.json"]


@pytest.mark.parametrize("case", ["empty", "truncated", "main_gain 9999", "drive_id 200"])
@pytest.mark.parametrize("kind", ["dyn2", "dyncan"])
def test_cli_refuses_to_start_with_one_line_and_exit_2(tmp_path: Path, case: str,
                                                       kind: str) -> None:
    raw, problem = BAD_CONTENT[case]
    path = tmp_path / "state.json"
    path.write_bytes(raw)
    proc = run_cli("sim", kind, "--ids", "1", "--state", str(path), "--duration", "5")
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()
    assert line.startswith("error: ") and str(path) in line and problem in line, line
    assert proc.stdout == ""  # it never listened
    assert path.read_bytes() == raw


def test_directory_missing_parent_and_unwritable_place_are_refused(tmp_path: Path) -> None:
    with pytest.raises(StateFileError, match="is a directory"):
        StateFile(tmp_path, DMM_STATE)
    with pytest.raises(StateFileError, match="does not exist - create it first"):
        StateFile(tmp_path / "nowhere" / "state.json", DMM_STATE)
    if os.geteuid() == 0:  # root writes anywhere but where the kernel refuses everyone
        place = Path("/sys/servobus-state-test.json")
    else:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o555)
        place = locked / "state.json"
    with pytest.raises(StateFileError, match="not writable"):
        StateFile(place, DMM_STATE)
    assert not place.exists()


def test_read_only_file_is_refused(tmp_path: Path) -> None:
    if os.geteuid() == 0:
        pytest.skip("root may write a read-only file; the check cannot be seen as root")
    path = tmp_path / "state.json"
    path.write_text(json.dumps(GOOD))
    path.chmod(0o444)
    with pytest.raises(StateFileError, match="read-only"):
        StateFile(path, DMM_STATE)


def test_a_second_simulator_on_the_same_file_refuses_to_start(tmp_path: Path) -> None:
    """Before: two processes on one file lost records 3 rounds out of 3."""
    path = tmp_path / "state.json"
    with sim("dyn2", "--fast", "--ids", "1", "--state", str(path)) as first:
        first.port()
        second = run_cli("sim", "dyn232", "--fast", "--ids", "2", "--state", str(path),
                         "--duration", "5")
        assert second.returncode == 2
        (line,) = second.stderr.splitlines()
        assert "in use by another simulator process" in line and str(path) in line
        assert first.alive()
    again = run_cli("sim", "dyn232", "--fast", "--ids", "2", "--state", str(path),
                    "--duration", "0.1")  # the lock went with the first process
    assert again.returncode == 0, again.stderr


def test_lock_holds_between_two_opens_in_one_process_too(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    held = StateFile(path, DMM_STATE)
    with pytest.raises(StateFileError, match="in use"):
        StateFile(path, DMM_STATE)
    held.save("1", {"drive_id": 1})  # the lock moves with the rewritten file
    with pytest.raises(StateFileError, match="in use"):
        StateFile(path, DMM_STATE)
    other = tmp_path / "other.json"
    # stores of one process share
    assert StateFile.shared(other, DMM_STATE) is StateFile.shared(other, DMM_STATE)


def test_values_survive_a_restart_other_records_are_kept_and_no_tmp_is_left(
        tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    other = {"drive_id": 9, "params": P.defaults(), "config": 0, "origin": 0, "writes": {}}
    path.write_text(json.dumps({"7": other}))
    (tmp_path / "state.json.tmp").write_text("left by a simulator killed mid-write")
    drive = VirtualDrive(1, eeprom=EepromStore(path, key="1"))
    assert not (tmp_path / "state.json.tmp").exists()  # cleaned at start
    for gain in range(30, 60):
        assert drive.set_param("main_gain", gain)
    assert drive.assign_id(4)
    records = parse_state(path.read_bytes(), str(path), DMM_STATE)
    assert records["7"] == other
    assert records["1"]["params"]["main_gain"] == 59 and records["1"]["drive_id"] == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.json"]


def test_a_failing_save_logs_once_and_the_drive_keeps_running(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Before: every parameter write dropped the client's connection."""
    where = tmp_path / "gone"
    where.mkdir()
    drive = VirtualDrive(1, eeprom=EepromStore(where / "state.json", key="1"))
    shutil.rmtree(where)
    with caplog.at_level(logging.WARNING, logger="servobus.sim"):
        for gain in (50, 51, 52):
            assert drive.set_param("main_gain", gain)
    assert drive.get_param("main_gain") == 52
    assert len([r for r in caplog.records if "cannot save" in r.getMessage()]) == 1


def test_kill_9_during_writes_leaves_a_valid_file_and_no_tmp_after_restart(
        tmp_path: Path) -> None:
    """40/40 kill -9 rounds kept valid JSON before, but left ``.tmp`` files behind."""
    path = tmp_path / "state.json"
    for round_ in range(3):
        proc = subprocess.Popen([*SERVOBUS, "sim", "dyn232", "--fast", "--ids", "1", "--state",
                                 str(path), "--duration", "20"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None
            port = int(proc.stdout.readline().rsplit(":", 1)[1])
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                writes = b"".join(c.encode(1, H.SET_MAIN_GAIN, 10 + i % 100)
                                  for i in range(2000))
                s.sendall(c.encode(1, DmmFunction.READ_DRIVE_STATUS) + writes)
                assert readable(s, 10.0)  # the status reply: the writes have begun
                time.sleep(0.01 * round_)  # the kill lands at varied points of the writes
                proc.send_signal(signal.SIGKILL)
        finally:
            proc.kill()
            proc.communicate()
        parse_state(path.read_bytes(), str(path), DMM_STATE)  # valid after every kill
    restarted = run_cli("sim", "dyn232", "--fast", "--ids", "1", "--state", str(path),
                        "--duration", "0.1")
    assert restarted.returncode == 0, restarted.stderr
    assert not Path(f"{path}.tmp").exists()
