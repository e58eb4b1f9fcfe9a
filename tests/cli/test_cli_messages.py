"""Messages in the axis's own units and names, advice only where it applies (issue 32, item 3).

In-process (``main([...])``): each case is one command a user typed, checked for the words it
must carry and for the advice that would mislead there (another axis's units, "inside the
range" where no range is involved, ``--baud`` on CAN or a machine, a link blamed for a rule).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from cli_rig import CELL

from servobus.cli import failures as F
from servobus.cli.main import main
from servobus.errors import DriveTimeout, InvalidValue, NotSupported, ProtocolError
from servobus.families.yzaim.family import axis_status
from servobus.machine import open_machine
from servobus.machine.config import parse_machine


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """``servobus ARGS`` in this process: exit code, stdout, stderr."""
    with pytest.raises(SystemExit) as info:
        main(list(args))
    out, err = capsys.readouterr()
    code = info.value.code
    return code if isinstance(code, int) else 0, out, err


def error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture
def cell(tmp_path: Path) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(CELL, encoding="utf-8")
    return path


# ------------------------------------------------------------------ units of the axis
@pytest.mark.parametrize("target", ["12,5", "1.25cm", "90°", "nan", "2.5rev", "90deg"])
def test_a_wrong_target_on_a_mm_axis_suggests_only_mm(
        capsys: pytest.CaptureFixture[str], cell: Path, target: str) -> None:
    code, _, err = run(capsys, "--machine", str(cell), "--axis", "x", "move", target)
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert repr(target) in line
    advice = line.replace(repr(target), "")  # what the line suggests, without the echo
    assert "mm" in advice
    for foreign in ("rev)", "2.5rev", "120cmd", "deg)", "90deg", "inside the range"):
        assert foreign not in advice, line


def test_speed_in_another_unit_names_the_axis_speed_unit(
        capsys: pytest.CaptureFixture[str], cell: Path) -> None:
    code, _, err = run(capsys, "--machine", str(cell), "--axis", "x", "speed", "30deg")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "mm/s" in line and "'30deg'" in line
    assert "RPM" not in line and "float" not in line and "inside the range" not in line


def test_speed_with_the_axis_unit_per_second_runs(
        capsys: pytest.CaptureFixture[str], cell: Path) -> None:
    code, out, _ = run(capsys, "--machine", str(cell), "--axis", "c", "speed", "-30deg/s",
                       "--for", "0.05")
    assert code == 0
    assert "-30 deg/s" in out


def test_speed_of_a_drive_is_rpm_and_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "speed", "30deg")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "rpm" in line and "--machine" in line and "not a valid float" not in line


# ------------------------------------------------------------------ advice by error kind
def test_a_machine_name_mqtt_cannot_carry_says_rename_not_range() -> None:
    from servobus.gateway.mqtt import check_topic_name

    with pytest.raises(InvalidValue) as info:
        check_topic_name("machine", "a/b")  # what `serve --mqtt` checks first
    code, line = F.describe(info.value)
    assert code == F.EXIT_USAGE
    assert "rename the machine" in line and "inside the range" not in line


def test_a_malformed_mqtt_url_gets_no_range_advice(
        capsys: pytest.CaptureFixture[str], cell: Path) -> None:
    code, _, err = run(capsys, "--machine", str(cell), "serve", "--opcua",
                       "opc.tcp://127.0.0.1:0", "--mqtt", "http://broker")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "mqtt://HOST:PORT" in line and "inside the range" not in line


def test_users_short_password_and_unknown_user(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    users = tmp_path / "users.json"
    monkeypatch.setattr("sys.stdin", io.StringIO("short\n"))
    code, _, err = run(capsys, "users", "add", "--file", str(users), "bob")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "password" in line and "unchanged" in line and "inside the range" not in line
    users.write_text(json.dumps({"users": {}}), encoding="utf-8")
    code, _, err = run(capsys, "users", "remove", "--file", str(users), "nobody")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "no user 'nobody'" in line and "users list" in line
    assert "inside the range" not in line


# ------------------------------------------------------------------ the actual cause
def test_wait_timeout_blames_the_time_not_the_link(
        capsys: pytest.CaptureFixture[str], cell: Path) -> None:
    code, _, err = run(capsys, "--machine", str(cell), "--axis", "x", "move", "100",
                       "--wait", "--wait-timeout", "0.05")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "still moving after 0.05 s" in line and "--wait-timeout" in line
    assert "--baud" not in line and "--id" not in line


@pytest.mark.parametrize(("url", "says", "never"), [
    ("sim://dyn232?ids=1&fast=1", "?ids=", "--baud"),
    ("sim://easycan?ids=1&fast=1", "?ids=", "--baud"),
])
def test_an_absent_virtual_drive_names_the_ids_not_the_wiring(
        capsys: pytest.CaptureFixture[str], url: str, says: str, never: str) -> None:
    code, _, err = run(capsys, "--url", url, "--id", "5", "--timeout", "0.02", "status")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert says in line and never not in line and "wiring" not in line


@pytest.mark.parametrize(("link", "says", "never"), [
    ("serial", "--baud", "bitrate"),
    ("can", "bitrate", "--baud"),
    ("network", "address", "--baud"),
    ("machine", "machine file", "--baud"),
])
def test_timeout_and_protocol_advice_name_only_what_the_link_has(
        link: str, says: str, never: str) -> None:
    for exc in (DriveTimeout("no reply from drive 3"), ProtocolError("bad frame")):
        code, line = F.describe(exc, link)
        assert code == F.EXIT_USAGE
        assert says in line and never not in line, line


def test_the_link_kind_comes_from_the_protocol_spec() -> None:
    """A CAN drive that does not answer (a DYN CAN client on a bus of EasyCan motors): the
    advice is the CAN one, found through the registry's ProtocolSpec.link (no --baud)."""
    from servobus.axis.registry import link_kind
    from servobus.axis.url import parse_url

    assert link_kind(parse_url("dyncan+pcan://PCAN_USBBUS1")) == "can"
    assert link_kind(parse_url("easycan+socketcand://h:1")) == "can"
    assert link_kind(parse_url("enip://10.0.0.2")) == "network"
    assert link_kind(parse_url("/dev/ttyUSB0")) == "serial"
    assert link_kind(parse_url("sim://easycan")) == "virtual"


def test_origin_home_where_the_family_has_none_is_refused_not_a_link_problem(
        tmp_path: Path) -> None:
    path = tmp_path / "home.toml"
    path.write_text('[axes.c]\nurl = "sim://easycan?fast=1"\nid = 1\nunit = "deg"\n'
                    'origin = "home"\n', encoding="utf-8")
    with pytest.raises(NotSupported) as info:
        open_machine(path, retry=True)  # the GUI's and gateway's way: it used to go offline
    code, line = F.describe(info.value, "machine")
    assert "origin" in str(info.value) and "check those links" not in line
    assert code == F.EXIT_USAGE


# ------------------------------------------------------------------ conflicting options
@pytest.mark.parametrize("option", [("--id", "2"), ("--baud", "9600"), ("--timeout", "1")])
def test_a_drive_option_on_a_machine_axis_is_a_usage_error(
        capsys: pytest.CaptureFixture[str], option: tuple[str, str]) -> None:
    code, out, err = run(capsys, "--axis", "x", *option, "status")
    line = error_line(err)
    assert code == F.EXIT_USAGE and out == ""
    assert f"{option[0]} would be ignored" in line


@pytest.mark.parametrize("command", [("scan", "--last", "2"), ("reset",)])
def test_a_machine_axis_command_names_its_own_link(
        capsys: pytest.CaptureFixture[str], cell: Path, command: tuple[str, ...]) -> None:
    code, out, err = run(capsys, "--machine", str(cell), "--axis", "c", *command)
    assert code == 0
    assert "sim://easycan?fast=1" in out + err
    assert "on sim://:" not in out + err and "of sim://," not in out


def test_two_spellings_of_one_drive_are_refused_in_the_machine_file() -> None:
    text = ('[axes.x]\nurl = "socket://127.0.0.1:4001"\nid = 1\n'
            '[axes.y]\nurl = "socket://127.0.0.1:4001/"\nid = 1\n')
    with pytest.raises(Exception, match="already axis x; two axes cannot be one drive"):
        parse_machine(text)
    ok = ('[axes.x]\nurl = "socket://127.0.0.1:4001"\nid = 1\n'
          '[axes.y]\nurl = "socket://127.0.0.1:4001/"\nid = 2\n')
    assert [a.name for a in parse_machine(ok).axes] == ["x", "y"]


def test_a_users_file_of_something_else_is_refused(tmp_path: Path, cell: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    users = tmp_path / "users.json"
    users.write_text('{"robot": "x"}', encoding="utf-8")
    code, out, err = run(capsys, "--machine", str(cell), "serve", "--opcua",
                         "opc.tcp://127.0.0.1:0", "--users", str(users))
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "is not a servobus users file" in line and "read-only" not in out + err


# ------------------------------------------------------------------ cosmetic
def test_decode_keeps_a_space_after_long_raw_bytes(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "decode", "--protocol", "modbus", "01", "03", "00", "00", "00",
                       "01", "84", "0a")
    assert code == 0
    assert out.startswith("01 03 00 00 00 01 84 0a id 1 read"), out


def test_no_minus_zero(capsys: pytest.CaptureFixture[str]) -> None:
    from servobus.cli.output import fixed

    assert fixed(-0.0, 3) == "0.000" and fixed(-0.00004, 4) == "0.0000"
    assert fixed(-0.5, 1) == "-0.5"
    code, out, _ = run(capsys, "--axis", "y", "position")  # direction -1: -0.0 mm
    assert code == 0 and "-0.0" not in out


def test_demo_header_names_the_default_id_not_none(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "one.toml"
    path.write_text('[axes.x]\nurl = "sim://dyn232?fast=1"\nunit = "mm"\nper_rev = 5.0\n',
                    encoding="utf-8")
    code, out, _ = run(capsys, "--machine", str(path), "status")
    assert code == 0 and "None" not in out and "id 0" in out


def test_a_disabled_yzaim_off_its_target_is_not_moving() -> None:
    status = axis_status(output_enable=0, alarm_code=0, motor_speed_word=0,
                         position_error=5000)
    assert not status.enabled and not status.moving and not status.in_position
    running = axis_status(output_enable=1, alarm_code=0, motor_speed_word=0,
                          position_error=5000)
    assert running.moving  # enabled, target not reached: its profile runs


def test_scan_of_the_builtin_drive_finds_the_id_status_shows(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "status")
    assert code == 0 and "id 0" in out.splitlines()[0]
    code, out, _ = run(capsys, "scan", "--ids", "1-8,12")
    assert code == 0 and out.startswith("no drive answered"), out
    code, out, _ = run(capsys, "scan", "--ids", "0-3")
    assert code == 0 and out.strip().endswith(": 0"), out


@pytest.mark.parametrize(("url", "cmd"), [("sim://dyn232?fast=1", True),
                                          ("sim://easycan?fast=1", False)])
def test_a_wrong_target_on_a_drive_names_command_units_only_where_it_has_them(
        capsys: pytest.CaptureFixture[str], url: str, cmd: bool) -> None:
    code, _, err = run(capsys, "--url", url, "move", "12,5")
    line = error_line(err)
    assert code == F.EXIT_USAGE
    assert "2.5rev" in line and ("120cmd" in line) == cmd
