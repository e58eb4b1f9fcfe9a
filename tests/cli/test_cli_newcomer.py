"""What a newcomer tripped on (issue 18, items 9-14), in-process: one line each, and right.

URLs (unknown and near-miss schemes and transports), ``move`` out of range, backups of another
family or protocol, ``--id`` against an ``enip://`` address, ``scan --ids`` and its progress,
and no Python ``None`` in what a person reads.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_rig import run

from servobus.axis import connect
from servobus.cli import failures as F


def one_error_line(err: str) -> str:
    assert err.count("\n") == 1 and err.startswith("error: "), err
    return err


# ------------------------------------------------------------------ 9: URLs
def test_an_unknown_scheme_lists_servobus_schemes_only(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "--url", "foo://x", "status")
    line = one_error_line(err)
    assert code == F.EXIT_USAGE
    for own in ("dyn232", "dyncan", "easycan", "enip", "modbus", "sim"):
        assert own in line
    for pyserial in ("alt", "hwgrep", "spy", "cp2110"):
        assert f" {pyserial}," not in line and f" {pyserial} " not in line
    assert "inside the range" not in line and "did you mean" not in line


@pytest.mark.parametrize(("url", "meant"), [
    ("enp://127.0.0.1", "enip://127.0.0.1"),
    ("dyncann+pcan://PCAN_USBBUS1", "dyncan+pcan://PCAN_USBBUS1"),
    ("dyn232+sockte://127.0.0.1:5", "dyn232+socket://127.0.0.1:5"),
    ("modbus+sockte://127.0.0.1:5", "modbus+socket://127.0.0.1:5"),
])
def test_a_near_miss_suggests_what_it_resembles(capsys: pytest.CaptureFixture[str], url: str,
                                                meant: str) -> None:
    code, _, err = run(capsys, "--url", url, "status")
    line = one_error_line(err)
    assert code == F.EXIT_USAGE
    assert f"did you mean {meant}?" in line
    assert "CAN bus" not in line and "inside the range" not in line


def test_socketcan_with_host_and_port_points_to_socketcand(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "--url", "dyncan+socketcan://127.0.0.1:29536", "status")
    line = one_error_line(err)
    assert code == F.EXIT_USAGE
    assert "dyncan+socketcand://127.0.0.1:29536" in line and "ip link" not in line


# ------------------------------------------------------------------ 11: backups
def test_a_backup_of_another_family_is_refused_naming_both(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    backup = tmp_path / "yzaim.json"
    code, _, err = run(capsys, "--url", "sim://modbus?fast=1", "params", "--save", str(backup))
    assert code == 0, err
    for action in ("--load", "--diff"):
        code, out, err = run(capsys, "--url", "sim://dyn232?fast=1", "params", action,
                             str(backup))
        line = one_error_line(err)
        assert code == F.EXIT_USAGE and out == ""
        assert "YZ-AIM" in line and "modbus" in line
        assert "DMM DYN2" in line and "dyn232" in line


def test_a_backup_of_another_protocol_of_the_family_is_restored_with_a_note(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    backup = tmp_path / "dyn232.json"
    code, _, err = run(capsys, "--url", "sim://dyn232?fast=1", "params", "--save", str(backup))
    assert code == 0, err
    code, _, err = run(capsys, "--url", "sim://dyncan?fast=1", "params", "--load",
                         str(backup))
    assert code == 0, err
    assert "saved over dyn232" in err and "over dyncan" in err


def test_a_json_file_without_format_says_what_it_is_not(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"main_gain": 40}))
    code, _, err = run(capsys, "params", "--load", str(other))
    line = one_error_line(err)
    assert code == F.EXIT_USAGE
    assert "None" not in line and "not a servobus parameter backup" in line


# ------------------------------------------------------------------ 14: None
def test_status_of_a_yzaim_motor_has_no_python_none(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "--url", "sim://modbus?fast=1", "status")
    assert code == 0, err
    assert "None" not in out
    assert "position_error" in out


# ------------------------------------------------------------------ 10: move out of reach
@pytest.mark.parametrize("url", ["sim://dyn232?fast=1", "sim://dyncan?fast=1", "sim://enip",
                                 "sim://easycan?fast=1", "sim://modbus?fast=1"])
def test_move_out_of_reach_names_the_value_as_typed_and_the_range_in_its_unit(
        capsys: pytest.CaptureFixture[str], url: str) -> None:
    code, _, err = run(capsys, "--url", url, "move", "999999999999")
    line = one_error_line(err)
    assert code == F.EXIT_USAGE
    assert "move 999999999999: outside the -" in line and " counts this drive reaches" in line
    code, _, err = run(capsys, "--url", url, "move", "--relative", "--", "-99999999.5rev")
    line = one_error_line(err)
    assert "move --relative -99999999.5rev: outside the -" in line
    assert " rev this drive reaches" in line and "counts" not in line


# ------------------------------------------------------------------ 12: --id on enip://
def test_an_id_that_changes_the_enip_address_is_shown(capsys: pytest.CaptureFixture[str]) -> None:
    """Decision (docs/axis.md "Drive ids"): --id keeps picking the daisy-chain neighbour
    B3.B2.B1.id, and says which address that is."""
    code, out, err = run(capsys, "--url", "sim://enip?ids=1,9", "--id", "9", "status")
    assert code == 0, err
    assert "note: --id 9 addresses 127.0.0.9" in err
    assert out.startswith("status of sim://enip?ids=1,9, id 9 at 127.0.0.9")
    code, _, err = run(capsys, "--url", "sim://enip?ids=1,9", "--json", "--id", "9", "position")
    assert code == 0 and "127.0.0.9" in err


def test_an_id_on_a_bus_adds_no_address(capsys: pytest.CaptureFixture[str]) -> None:
    url = "sim://dyncan?ids=1,9&fast=1"
    code, out, err = run(capsys, "--url", url, "--id", "9", "status")
    assert code == 0, err
    assert "addresses" not in err and out.startswith(f"status of {url}, id 9\n")


# ------------------------------------------------------------------ 13: scan
def test_scan_ids_narrows_and_says_how_long_it_may_take(
        capsys: pytest.CaptureFixture[str]) -> None:
    url = "sim://modbus?ids=3,12&fast=1"
    with connect(url) as axis:  # the wait per id: the RTU deadline of a one-register read
        per_id_ms = round(axis.ping_deadline() * 1000)
    assert 50 < per_id_ms < 70  # 19200 baud: ~10 ms on the wire + t3.5 + 50 ms turnaround
    code, out, err = run(capsys, "--url", url, "scan", "--ids", "1-8,12")
    assert code == 0, err
    assert out == f"found 2 drive(s) on {url}: 3 12\n"
    assert (f"scanning 9 id(s) (1-8,12) on {url}: about {9 * per_id_ms / 1000:.1f} s "
            f"({per_id_ms} ms per absent id)") in err
    code, out, err = run(capsys, "--url", url, "--json", "scan", "--ids", "12,3")
    assert code == 0 and json.loads(out) == [3, 12]


@pytest.mark.parametrize(("ids", "says"), [("1-x", "1-8,12"), ("8-1", "low-high"),
                                           ("0", "not in this protocol's ids 1..")])
def test_scan_refuses_bad_ids(capsys: pytest.CaptureFixture[str], ids: str, says: str) -> None:
    code, _, err = run(capsys, "--url", "sim://dyncan?fast=1", "scan", "--ids", ids)
    assert code == F.EXIT_USAGE and says in one_error_line(err)


# ------------------------------------------------------------------ 14: "done at"
@pytest.mark.parametrize("relative", [False, True])
def test_done_at_explains_its_distance_from_the_target(capsys: pytest.CaptureFixture[str],
                                                       relative: bool) -> None:
    args = ["move", *(["--relative"] if relative else []), "1rev", "--wait"]
    code, out, err = run(capsys, "--url", "sim://dyn232?fast=1", *args)
    assert code == 0, err
    verb = "moving by" if relative else "moving to"
    assert out.startswith(f"{verb} 65536 counts; done at "), out
    done = int(out.split("done at ")[1].split()[0])
    if done == 65536:
        assert "on the target" in out
    else:
        assert f"{done - 65536:+d} from the target: inside the drive's in-position window" in out
    code, out, err = run(capsys, "--url", "sim://dyn232?fast=1", "--json", *args)
    doc = json.loads(out)
    assert doc["target"] == 65536 and abs(doc["position"] - 65536) <= doc["window"]


@pytest.mark.parametrize("missing", ["version", "protocol", "drive_id"])
def test_a_backup_missing_a_field_says_missing(capsys: pytest.CaptureFixture[str],
                                               tmp_path: Path, missing: str) -> None:
    doc = {"format": "servobus.params", "version": 1, "protocol": "dyn232", "drive_id": 1,
           "params": {"main_gain": 40}}
    del doc[missing]
    path = tmp_path / "backup.json"
    path.write_text(json.dumps(doc))
    code, _, err = run(capsys, "params", "--load", str(path))
    line = one_error_line(err)
    assert code == F.EXIT_USAGE and f"{missing} missing" in line and "None" not in line
