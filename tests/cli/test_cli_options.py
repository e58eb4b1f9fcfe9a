"""Command-line parsing and error mapping, in-process (click's CliRunner and plain calls).

Negative numbers as arguments, ``--json`` after the command, seconds that must be finite and
positive, ``set`` offering what the protocol can reach, the exit-code table, the Ctrl-C
motion guard, hex-text detection, and the built-in drive taking the id asked for.
"""

from __future__ import annotations

import json
import subprocess
import sys

import click
import pytest
from click.testing import CliRunner, Result
from hypothesis import given
from hypothesis import strategies as st

from servobus.cli import failures as F
from servobus.cli.context import CliContext
from servobus.cli.main import cli
from servobus.cli.motion_guard import STOPPED, stop_on_interrupt
from servobus.cli.param_types import ReachableParam, Seconds, reachable_params
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    NotSupported,
    ServobusError,
)
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.sniff import looks_like_hex_text

FAST = "sim://dyn2?fast=1"


def invoke(*args: str) -> Result:
    return CliRunner().invoke(cli, list(args))


# ------------------------------------------------------------------ parsing
@pytest.mark.parametrize(("args", "key", "value"), [
    (("move", "-120"), "counts", -120),
    (("move", "--relative", "-120"), "counts", -120),
    (("move", "-120", "--relative"), "counts", -120),
    (("move", "--", "-120"), "counts", -120),
    (("move", "-0.5rev"), "counts", -32_768),
    (("move", "-90deg", "--relative"), "counts", -16_384),
    (("move", "-120cmd"), "command_units", -120),
])
def test_negative_numbers_are_arguments(args: tuple[str, ...], key: str, value: int) -> None:
    result = invoke("--port", FAST, "--json", *args)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)[key] == value


def test_negative_speed_and_profile_without_double_dash() -> None:
    result = invoke("--port", FAST, "speed", "-300", "--for", "0.1", "--json")  # issue 27: held
    assert result.exit_code == 0 and json.loads(result.stdout)["speed_command"] == -300
    result = invoke("--json", "profile", "-140000")
    assert result.exit_code == 0 and json.loads(result.stdout)
    result = invoke("--port", FAST, "set", "main_gain", "-1")
    assert isinstance(result.exception, ArgumentRangeError)  # a number, refused by its range


@pytest.mark.parametrize("args", [("move", "-x", "5"), ("move", "--fast", "5"),
                                  ("status", "-q"), ("move", "-1x")])
def test_other_dash_tokens_are_still_unknown_options(args: tuple[str, ...]) -> None:
    result = invoke(*args)
    assert result.exit_code == 2 and "No such option" in result.output


@pytest.mark.parametrize("where", ["before", "after"])
def test_json_before_or_after_the_command(where: str) -> None:
    args = ["--port", FAST, "--json", "status"] if where == "before" else \
        ["--port", FAST, "status", "--json"]
    result = invoke(*args)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["in_position"] is True


def test_every_command_takes_json_after_it() -> None:
    for name, command in cli.commands.items():
        if isinstance(command, click.Group):
            continue
        assert any("--json" in p.opts for p in command.params), name


@pytest.mark.parametrize(("text", "ok"), [
    ("0.5", 0.5), ("3", 3.0), ("-1", None), ("0", None), ("nan", None), ("inf", None),
    ("-inf", None), ("soon", None),
])
def test_seconds_refuses_what_cannot_be_a_deadline(text: str, ok: float | None) -> None:
    if ok is None:
        with pytest.raises(click.BadParameter):
            Seconds().convert(text, None, None)
    else:
        assert Seconds().convert(text, None, None) == ok
    assert Seconds(allow_zero=True).convert("0", None, None) == 0.0
    with pytest.raises(click.BadParameter):
        Seconds(maximum=5.0).convert("6", None, None)


def test_set_offers_what_the_protocol_reaches() -> None:
    reach = reachable_params()
    assert reach["dyn232"] == tuple(c.PARAM_FUNCTIONS)
    assert "line_num" in reach["dyncan"]
    assert "torque_limit" not in reach["dyn232"] + reach["dyncan"]

    def convert(name: str, can: str | None) -> str:
        obj = CliContext(url_option=None, port=None, can=can, drive_id_option=1, baud=None,
                         json=False, timeout=None)
        ctx = click.Context(cli, obj=obj)
        return ReachableParam().convert(name, None, ctx)

    assert convert("line_num", "virtual:x") == "line_num"
    with pytest.raises(click.BadParameter, match="not reachable over dyn232"):
        convert("line_num", None)
    with pytest.raises(click.BadParameter, match="not reachable over dyncan"):
        convert("torque_limit", "virtual:x")  # in the DMM table (DYN5's), not on CAN
    with pytest.raises(click.BadParameter, match="unknown parameter 'bogus'"):
        convert("bogus", "virtual:x")
    result = invoke("set", "--help")
    assert "over dyn232: main_gain" in result.output


# ------------------------------------------------------------------ decode / sniff
def test_decode_empty_can_frame_is_an_error_not_a_zero() -> None:
    result = invoke("decode", "02e#")
    assert result.exit_code == F.EXIT_DIFFERENT
    assert "invalid frame: GENERAL_READ takes 1 (request) or 1..4 (reply)" in result.stdout
    assert "GENERAL_READ 0" not in result.stdout
    result = invoke("decode", "029#", "02e#1b")  # an empty status read is a valid request
    assert result.exit_code == 0


def test_hex_text_detection() -> None:
    assert looks_like_hex_text(b"03 a3 ff 88 ad\n")
    assert looks_like_hex_text(b"0x03,0xa3;ff:88")
    assert not looks_like_hex_text(b"")
    assert not looks_like_hex_text(b" \n")
    assert not looks_like_hex_text(c.encode(3, DmmFunction.GO_RELATIVE_POS, -120))


@given(st.integers(0, 63), st.sampled_from(c.HOST_FUNCTIONS), st.integers(-1000, 1000))
def test_a_raw_packet_never_looks_like_hex_text(drive_id: int, function: c.HostFunction,
                                                value: int) -> None:
    assert not looks_like_hex_text(c.encode(drive_id, function, value))


# ------------------------------------------------------------------ exit codes
@pytest.mark.parametrize(("exc", "code", "says"), [
    (DriveAlarm("drive 1 alarm lost_phase (code 2)"), F.EXIT_FAULT, "alarm lost_phase"),
    (DriveError("drive 1: invalid data"), F.EXIT_FAULT, "invalid data"),
    (DriveTimeout("no reply from drive 3"), F.EXIT_USAGE, "check --id"),
    (ConnectionLost("stream is closed"), F.EXIT_USAGE, "connection lost: stream is closed"),
    (ConnectionResetError(104, "Connection reset by peer"), F.EXIT_USAGE, "connection lost"),
    (ArgumentRangeError("rpm 99999 is outside"), F.EXIT_USAGE, "nothing was sent"),
    (NotSupported("no torque limit on DYN2", "dyn2"), F.EXIT_USAGE, "lacks the feature"),
    (FileNotFoundError(2, "No such file or directory", "x.bin"), F.EXIT_USAGE,
     "No such file or directory: x.bin - check the path"),
    (OSError(98, "Address already in use"), F.EXIT_USAGE, "Address already in use"),
    (KeyboardInterrupt(), F.EXIT_INTERRUPTED, "interrupted by Ctrl-C - nothing was moving"),
    (F.Terminated(), F.EXIT_INTERRUPTED, "interrupted by SIGTERM"),
    (F.CliError("what\nhappened.", "do this"), F.EXIT_USAGE, "error: what happened - do this"),
    (RuntimeError("boom"), F.EXIT_USAGE, "servobus bug"),
    (ServobusError("cannot serve on :1 - pick another port"), F.EXIT_USAGE,
     "error: cannot serve on :1 - pick another port"),
])
def test_describe(exc: BaseException, code: int, says: str) -> None:
    got_code, line = F.describe(exc)
    assert got_code == code
    assert line.startswith("error: ") and "\n" not in line and " - " in line
    assert says in line


class FakeAxis:
    def __init__(self, fail: bool = False) -> None:
        self.stops = 0
        self.fail = fail

    def stop(self) -> None:
        self.stops += 1
        if self.fail:
            raise ConnectionLost("stream is closed")


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, F.Terminated])
def test_motion_guard_stops_then_reports(interrupt: type[KeyboardInterrupt]) -> None:
    axis = FakeAxis()
    with pytest.raises(F.Interrupted) as info, stop_on_interrupt(axis):  # type: ignore[arg-type]
        raise interrupt()
    assert axis.stops == 1 and info.value.outcome == STOPPED
    assert info.value.signal_name == ("SIGTERM" if interrupt is F.Terminated else "Ctrl-C")
    assert F.describe(info.value)[0] == F.EXIT_INTERRUPTED


def test_motion_guard_says_when_the_stop_failed() -> None:
    axis = FakeAxis(fail=True)
    with pytest.raises(F.Interrupted) as info, stop_on_interrupt(axis):  # type: ignore[arg-type]
        raise KeyboardInterrupt
    assert "the stop command failed" in info.value.outcome
    assert "may still be moving" in F.describe(info.value)[1]


def test_motion_guard_leaves_other_errors_alone() -> None:
    axis = FakeAxis()
    with pytest.raises(DriveTimeout), stop_on_interrupt(axis):  # type: ignore[arg-type]
        raise DriveTimeout("still moving after 30 s")
    assert axis.stops == 0


# ------------------------------------------------------------------ entry point
@pytest.mark.slow  # a real process
def test_no_arguments_prints_help_and_version_works() -> None:
    proc = subprocess.run([sys.executable, "-m", "servobus"], capture_output=True, text=True,
                          timeout=30)
    assert proc.returncode == 0 and "Usage: servobus" in proc.stdout and not proc.stderr
    proc = subprocess.run([sys.executable, "-m", "servobus", "--version"], capture_output=True,
                          text=True, timeout=30)
    assert proc.returncode == 0 and proc.stdout.startswith("servobus, version ")


# ------------------------------------------------------------------ sim:// default id
def test_builtin_drive_takes_the_id_asked_for() -> None:
    from servobus.axis import connect
    from servobus.protocols.dyn232.inprocess import parse_sim_url

    with connect("sim://dyn2?fast=1", drive_id=1, timeout=0.5) as axis:
        assert axis.read_id() == 1
    assert parse_sim_url("sim://dyn2", default_id=7).ids == (7,)
    assert parse_sim_url("sim://dyn2?ids=2,3", default_id=7).ids == (2, 3)
    assert parse_sim_url("sim://dyn2", default_id=c.BROADCAST_ID).ids == (c.FACTORY_ID,)


def test_motion_guard_off_the_main_thread() -> None:
    """signal.signal only works on the main thread; the guard must still stop the axis."""
    import threading

    axis, caught = FakeAxis(), []

    def body() -> None:
        try:
            with stop_on_interrupt(axis):  # type: ignore[arg-type]
                raise KeyboardInterrupt
        except F.Interrupted as exc:
            caught.append(exc.outcome)

    thread = threading.Thread(target=body)
    thread.start()
    thread.join(5)
    assert caught == [STOPPED] and axis.stops == 1
