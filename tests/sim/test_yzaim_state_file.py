"""The YZ-AIM ``--state`` file is as safe as the DMM one (issue 17.4): checked whole at
start-up and refused in one line (exit 2, file untouched), locked against a second simulator,
no other motor's record dropped, a deeply nested file one line naming the file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sim_abuse_rig import run_cli, sim

from servobus.axis.connect import connect
from servobus.families.yzaim import registers as Y
from servobus.sim.core.state_file import StateFile, StateFileError
from servobus.sim.dmm.eeprom import EepromStore
from servobus.sim.yzaim.fleet import make_motors, record_positions
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.sim.yzaim.store import YZAIM_STATE, YzaimStore

pytestmark = pytest.mark.timeout(60)

TWO = {"1": {"registers": {"target_speed": 700}, "position": 1234, "saves": 1},
       "2": {"registers": {"target_speed": 900, "device_address": 2}, "position": -5,
             "saves": 3}}
TRUNCATED = json.dumps(TWO).encode()[:-1]  # records 1 and 2, the final "}" missing
NESTED = b"[" * 100_000 + b"]" * 100_000
BAD: dict[str, tuple[bytes, str]] = {
    "truncated": (TRUNCATED, "not valid JSON"),
    "empty": (b"", "is empty"),
    "list": (b"[]", "holds a list, expected an object of motor records"),
    "nested": (NESTED, "nests too deeply"),
    "nested record": (b'{"1": ' + b'{"a": ' * 50_000 + b"0" + b"}" * 50_001,
                      "nests too deeply"),
    "key 0": (b'{"0": {}}', "device address 1..254"),
    "key not a number": (b'{"x": {}}', "device address"),
    "record not an object": (b'{"1": 3}', "must be an object"),
    "unknown field": (b'{"1": {"colour": 1}}', "unknown field 'colour'"),
    "not a saved register": (b'{"1": {"registers": {"modbus_enable": 1}}}',
                             "'modbus_enable' is not a saved register"),
    "unknown register": (b'{"1": {"registers": {"turbo": 1}}}', "not a saved register"),
    "out of range": (b'{"1": {"registers": {"device_address": 999}}}',
                     "device_address 999 is outside 1..254"),
    "float": (b'{"1": {"registers": {"target_speed": 7.5}}}', "must be an integer"),
    "bool": (b'{"1": {"registers": {"target_speed": true}}}', "must be an integer"),
    "position beyond int32": (b'{"1": {"position": 4294967296}}', "position 4294967296"),
    "negative saves": (b'{"1": {"saves": -1}}', "saves -1 is outside"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_invalid_content_is_refused_with_the_file_named_and_left_unchanged(
        tmp_path: Path, case: str) -> None:
    """Before: the record was ignored, the motor ran on defaults (nested: RecursionError)."""
    raw, problem = BAD[case]
    path = tmp_path / "yzaim.json"
    path.write_bytes(raw)
    with pytest.raises(StateFileError) as err:
        YzaimStore(path, key="1")
    message = str(err.value)
    assert str(path) in message and problem in message and "\n" not in message, message
    assert path.read_bytes() == raw
    assert sorted(p.name for p in tmp_path.iterdir()) == ["yzaim.json"]


def test_the_sim_url_refuses_a_corrupt_file_too(tmp_path: Path) -> None:
    path = tmp_path / "yzaim.json"
    path.write_bytes(TRUNCATED)
    for kind in ("easycan", "modbus"):
        with pytest.raises(StateFileError, match="not valid JSON"):
            connect(f"sim://{kind}?state={path}", drive_id=1)
    assert path.read_bytes() == TRUNCATED


def test_other_motors_records_are_kept_when_one_motor_saves(tmp_path: Path) -> None:
    """Before: motor 1's save rewrote the file holding motor 1 only."""
    path = tmp_path / "yzaim.json"
    path.write_text(json.dumps(TWO))
    (motor,) = make_motors([1], state=str(path))
    assert motor.store.registers["target_speed"] == 700 and motor.store.position == 1234
    motor.power_cycle()  # records the position: the file is rewritten
    kept = json.loads(path.read_text())
    assert kept["2"] == TWO["2"]
    assert kept["1"]["registers"]["target_speed"] == 700 and kept["1"]["saves"] == 1


def test_every_motor_of_one_process_shares_the_file(tmp_path: Path) -> None:
    path = tmp_path / "yzaim.json"
    one, two = make_motors([1, 2], state=str(path))
    one.power_cycle()
    two.power_cycle()
    again = YzaimMotor(1, store=YzaimStore(path, key="1"))  # a restart inside the process
    assert again.store.loaded
    assert set(json.loads(path.read_text())) == {"1", "2"}


def test_a_dmm_and_a_yzaim_simulator_cannot_share_one_file(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    store = YzaimStore(path, key="1")
    with pytest.raises(StateFileError, match="in use by this process for motor records"):
        EepromStore(path, key="1")
    assert store.path == path


def test_lock_holds_in_one_process(tmp_path: Path) -> None:
    path = tmp_path / "yzaim.json"
    held = StateFile(path, YZAIM_STATE)
    with pytest.raises(StateFileError, match="in use by another simulator process"):
        StateFile(path, YZAIM_STATE)
    assert held.records == {}


@pytest.mark.parametrize("kind", ["easycan", "modbus"])
@pytest.mark.parametrize("case", ["truncated", "nested", "out of range"])
def test_cli_refuses_to_start_with_one_line_and_exit_2(tmp_path: Path, kind: str,
                                                       case: str) -> None:
    raw, problem = BAD[case]
    path = tmp_path / "state.json"
    path.write_bytes(raw)
    proc = run_cli("sim", kind, "--ids", "1,2", "--state", str(path), "--duration", "5")
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()
    assert line.startswith("error: ") and str(path) in line and problem in line, line
    assert "servobus bug" not in line
    assert proc.stdout == ""  # it never listened
    assert path.read_bytes() == raw


def test_a_second_simulator_on_the_same_file_refuses_to_start(tmp_path: Path) -> None:
    """Before: a second simulator started on the file and the two lost each other's records."""
    path = tmp_path / "state.json"
    with sim("easycan", "--fast", "--ids", "1", "--state", str(path)) as first:
        assert first.line().startswith("listening on ")
        second = run_cli("sim", "modbus", "--fast", "--ids", "2", "--state", str(path),
                         "--duration", "5")
        assert second.returncode == 2
        (line,) = second.stderr.splitlines()
        assert "in use by another simulator process" in line and str(path) in line
        assert first.alive()
    again = run_cli("sim", "modbus", "--fast", "--ids", "2", "--state", str(path),
                    "--duration", "0.1")  # the lock went with the first process
    assert again.returncode == 0, again.stderr
    assert "1" in json.loads(path.read_text())  # the first simulator's record is kept


@pytest.mark.parametrize("model", ["57AIM30C", "42AIM15C"])
def test_a_stopped_simulator_records_each_position_for_the_next_start(
        tmp_path: Path, model: str) -> None:
    """1: "communication mode: power-off record position" (issue 34: `sim modbus` lost it).
    A multi-turn model (57AIM) comes back at its position; a single-turn one (42AIM) reads
    only its angle within the turn, as after a power cycle."""
    path = str(tmp_path / "motors.json")
    (motor,) = make_motors([1], state=path, model=model)
    target = 3 * Y.COUNTS_PER_REV + 1234
    motor.write_words(Y.PAIR_BY_NAME["absolute_position"].low, [target & 0xFFFF, target >> 16])
    motor.advance(2.0)
    here = motor.position
    assert abs(here - target) < 50
    record_positions([motor])
    (again,) = make_motors([1], state=path, model=model)
    assert again.position == (here if model == "57AIM30C" else here % Y.COUNTS_PER_REV)
