"""Issue 32: ``servobus shell``, an interactive session with the drive or machine bound,
fed on standard input in-process: statements run on the bound Axis, errors print and the
session goes on, Tab completion on the session's names, the history file, and every axis
stopped on Ctrl-C, on leaving and on SIGTERM.
"""

from __future__ import annotations

import io
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from servobus.axis import sync
from servobus.cli import failures as F
from servobus.cli.main import main


@pytest.fixture(autouse=True)
def _no_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("SERVOBUS_MACHINE", "SERVOBUS_URL", "SERVOBUS_ID", "SERVOBUS_HISTORY"):
        monkeypatch.delenv(name, raising=False)


@pytest.fixture
def stops(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[int]]:
    """The drive ids every sync Axis.stop() was called for."""
    seen: list[int] = []
    real = sync.Axis.stop

    def stop(self: sync.Axis) -> None:
        seen.append(self.drive_id)
        real(self)

    monkeypatch.setattr(sync.Axis, "stop", stop)
    yield seen


def shell(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, lines: str,
          *args: str, history: Path | None = None) -> tuple[int, str, str]:
    monkeypatch.setattr(sys, "stdin", io.StringIO(lines))
    where = ["--history", str(history) if history is not None else ""]
    with pytest.raises(SystemExit) as info:
        main([*args, "shell", *where])
    out, err = capsys.readouterr()
    code = info.value.code
    return code if isinstance(code, int) else 0, out, err


def test_a_session_on_a_drive_runs_statements_on_axis_and_keeps_its_history(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        tmp_path: Path, stops: list[int]) -> None:
    history = tmp_path / "history"
    history.write_text("axis.status()\n", encoding="utf-8")  # an earlier session's line
    lines = ("axis.move_by(axis.revs(1), wait=True)\n"
             "print(round(axis.position() / axis.counts_per_rev, 2))\n"
             "axis.write_param('nope', 1)\n"
             "1 / 0\n"
             "for n in range(2):\n"
             "    print('n', n)\n"
             "\n"
             "import readline\n"
             "print(readline.get_completer()('axis.move_b', 0))\n"
             "print(readline.get_history_item(1))\n")
    code, out, err = shell(capsys, monkeypatch, lines, "--url", "sim://dyn232?fast=1",
                           history=history)
    assert code == 0, err
    assert out.splitlines() == ["1.0", "n 0", "n 1", "axis.move_by(", "axis.status()"]
    assert err.startswith("servobus shell: axis = drive 0 (sim://dyn232?fast=1, DMM DYN2/DC2/"
                          "DYN4 over dyn232); servobus. Tab completes")
    assert "error: 'nope' is not a parameter dyn232 reaches" in err  # one line, no traceback
    assert "ZeroDivisionError: division by zero" in err  # any other error: its traceback
    kept = history.read_text(encoding="utf-8").splitlines()
    assert kept[0] == "axis.status()" and kept[1] == "axis.move_by(axis.revs(1), wait=True)"
    assert kept[-1] == "print(readline.get_history_item(1))" and "" not in kept
    assert stops == [0]  # leaving the session stopped the drive


def test_a_session_on_a_machine_binds_it_and_its_axes(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    lines = ("print(sorted(machine.axes), axis is x, y.unit, c.unit)\n"
             "r = machine.move_together({'x': 5, 'y': 6}, wait=True)\n"
             "print(round(x.position(), 2), round(y.position(), 2))\n")
    code, out, err = shell(capsys, monkeypatch, lines, "--axis", "x")
    assert code == 0, err
    assert out.splitlines() == ["['c', 'x', 'y'] True mm deg", "5.0 6.0"]
    assert "servobus shell: machine = virtual-cell; axes x, y, c" in err


def test_ctrl_c_stops_the_motion_and_the_session_goes_on(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        stops: list[int]) -> None:
    lines = ("axis.turn(300)\n"
             "raise KeyboardInterrupt\n"
             "print(axis.wait_idle(5).moving)\n")
    code, out, err = shell(capsys, monkeypatch, lines, "--url", "sim://easycan?fast=1",
                           "--id", "1")
    assert code == 0, err
    assert "KeyboardInterrupt: the drive was told to stop" in err
    assert out.splitlines()[-1] == "False" and stops == [1, 1]  # Ctrl-C, then leaving


def test_sigterm_stops_the_drive_and_ends_the_session(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        stops: list[int]) -> None:
    lines = ("from servobus.cli.failures import Terminated\n"
             "raise Terminated()\n"
             "print('not run')\n")
    code, out, err = shell(capsys, monkeypatch, lines, "--url", "sim://dyn232?fast=1")
    assert code == F.EXIT_INTERRUPTED and "not run" not in out
    assert "SIGTERM" in err.splitlines()[-1] and stops == [0]


@pytest.mark.parametrize(("statement", "code"), [("exit()", 0), ("exit(3)", 3)])
def test_exit_leaves_the_session(capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch, stops: list[int],
                                 statement: str, code: int) -> None:
    got, out, err = shell(capsys, monkeypatch, f"{statement}\nprint('not run')\n",
                          "--url", "sim://dyn232?fast=1")
    assert got == code and "not run" not in out and stops == [0]
    assert err.startswith("servobus shell: ") and "error" not in err
