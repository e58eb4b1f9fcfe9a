"""Every mistake a user makes at the terminal ends with one stderr line and a documented code.

Table-driven, one test per case. Each case runs in-process through ``servobus.cli.main.main``
(the function behind the console script: the same stderr line, the same ``sys.exit`` code),
with stdout/stderr captured and stdin empty. A handful run again end to end as real processes
(``python -m servobus``), which also proves the console entry, the exit code the shell sees and
that nothing more is printed at interpreter exit.
"""

from __future__ import annotations

import io
import json
import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from rig import free_port

from servobus.cli.failures import EXIT_FAULT, EXIT_USAGE
from servobus.cli.main import DEBUG_ENV, QUIET_LOGGERS, main
from servobus.families.dmm import params as P

SERVOBUS = [sys.executable, "-m", "servobus"]
CASE_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class Case:
    id: str
    args: tuple[str, ...]
    code: int
    says: str  # a piece of the one stderr line
    env: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class Outcome:
    code: int
    stdout: str
    stderr: str


DEAD_SERIAL = ("--port", "socket://127.0.0.1:{closed}")
DEAD_CAN = ("--can", "socketcand:127.0.0.1:{closed}", "--id", "1")
#: Every command that talks to a drive, with valid arguments.
DRIVE_COMMANDS: dict[str, tuple[str, ...]] = {
    "status": ("status",),
    "position": ("position",),
    "speed": ("speed", "100"),
    "move": ("move", "100"),
    "move-wait": ("move", "--relative", "--wait", "-100"),
    "stop": ("stop",),
    "params": ("params",),
    "params-save": ("params", "--save", "{tmp}/saved.json"),
    "params-load": ("params", "--load", "{backup}"),
    "params-diff": ("params", "--diff", "{backup}"),
    "set": ("set", "main_gain", "41"),
    "scan": ("scan", "--last", "2"),
    "demo": ("demo", "--yes"),
}

CASES: list[Case] = [
    # --- nothing there (issue 7: socketcand took 10.6 s and 200,000 log lines)
    *(Case(f"dead-port-{name}", (*DEAD_SERIAL, *args), EXIT_USAGE,
           "cannot open socket://127.0.0.1:") for name, args in DRIVE_COMMANDS.items()),
    # The CAN path shares open_axis with the serial one: a representative few.
    *(Case(f"dead-socketcand-{name}", (*DEAD_CAN, *DRIVE_COMMANDS[name]), EXIT_USAGE,
           "cannot reach socketcand at 127.0.0.1:")
      for name in ("status", "move-wait", "params-load", "scan", "demo")),
    Case("dead-socketcand-sniff", ("--can", "socketcand:127.0.0.1:{closed}", "sniff"),
         EXIT_USAGE, "cannot reach socketcand"),
    Case("dead-tap-sniff", ("sniff", "--tap", "tcp://127.0.0.1:{closed}"), EXIT_USAGE,
         "cannot open tcp://127.0.0.1:"),
    Case("pcan-driver-missing", ("--can", "pcan:PCAN_USBBUS1", "--id", "1", "status"),
         EXIT_USAGE, "PCAN-Basic"),
    Case("unknown-can-interface", ("--can", "nosuchbus:0", "--id", "1", "status"), EXIT_USAGE,
         "cannot open CAN bus dyncan+nosuchbus://0"),
    Case("dead-enip", ("--url", "enip://127.0.0.1:{closed}", "status"), EXIT_USAGE,
         "cannot reach enip://127.0.0.1:"),
    Case("bad-serial-device", ("--port", "/dev/servobus-no-such-port", "status"), EXIT_USAGE,
         "cannot open /dev/servobus-no-such-port"),
    Case("bad-sim-option", ("--port", "sim://dyn2?speed=9", "status"), EXIT_USAGE,
         "unknown option ?speed="),
    Case("absent-drive-id", ("--port", "sim://dyn2?ids=1&fast=1", "--id", "5", "--timeout",
                             "0.05", "status"), EXIT_USAGE, "no reply from drive 5"),
    Case("can-broadcast-id", ("--can", "virtual:servobus-errors", "--id", "0", "status"),
         EXIT_USAGE, "drive id 0 is outside 1..63 (0 = broadcast)"),
    # --- files
    Case("sniff-missing-file", ("sniff", "--from-file", "{tmp}/nope.bin"), EXIT_USAGE,
         "cannot read"),
    Case("sniff-hex-text-without-hex", ("sniff", "--from-file", "{hexfile}"), EXIT_USAGE,
         "add --hex"),
    Case("sniff-hex-flag-on-binary", ("sniff", "--hex", "--from-file", "{binfile}"), EXIT_USAGE,
         "is not hex text"),
    Case("params-load-missing-file", ("params", "--load", "{tmp}/nope.json"), EXIT_USAGE,
         "cannot read"),
    Case("params-load-not-a-backup", ("params", "--load", "{hexfile}"), EXIT_USAGE,
         "is not JSON"),
    Case("params-save-unwritable", ("--port", "sim://dyn2?fast=1", "params", "--save",
                                    "{tmp}/no/such/dir/b.json"), EXIT_USAGE, "cannot write"),
    # --- values refused at parse time
    *(Case(f"timeout-{bad}", ("--timeout", bad, "status"), EXIT_USAGE, "--timeout")
      for bad in ("-1", "0", "nan", "inf", "soon")),
    Case("wait-timeout-nan", ("move", "--wait", "--wait-timeout", "nan", "5"), EXIT_USAGE,
         "--wait-timeout"),
    Case("per-id-nan", ("scan", "--per-id", "nan"), EXIT_USAGE, "--per-id"),
    Case("set-out-of-range-negative", ("set", "main_gain", "-1"), EXIT_USAGE,
         "main_gain=-1 is outside the allowed range 1..127"),
    Case("set-unreachable-over-dyn232", ("set", "torque_limit", "3"), EXIT_USAGE,
         "not reachable over dyn232"),
    Case("set-unknown-name", ("set", "bogus", "3"), EXIT_USAGE, "unknown parameter 'bogus'"),
    Case("speed-out-of-range", ("speed", "99999"), EXIT_USAGE, "outside"),
    Case("unknown-option", ("status", "--bogus"), EXIT_USAGE, "No such option '--bogus'"),
    Case("missing-argument", ("move",), EXIT_USAGE, "Missing argument"),
    Case("not-a-number", ("move", "far"), EXIT_USAGE, "'far': write counts (16384)"),
    Case("unknown-command", ("fly",), EXIT_USAGE, "No such command 'fly'"),
    # --- decode: bytes with errors exit 1 (like cmp) and say so once
    Case("decode-empty-can-frame", ("decode", "02e#"), EXIT_FAULT, "not valid"),
    Case("decode-bad-hex", ("decode", "03", "zz"), EXIT_USAGE, "not hex"),
]


BY_ID = {c.id: c for c in CASES}
#: The cases that also run as real processes: one per way of failing (a dead TCP port, the
#: socketcand probe, an absent drive, a CAN bus opened and closed, click's usage errors, a
#: decode fault with exit 1, a file that cannot be read).
END_TO_END = ("dead-port-move-wait", "dead-socketcand-status", "absent-drive-id",
              "can-broadcast-id", "unknown-command", "decode-empty-can-frame",
              "params-load-missing-file")


@pytest.fixture
def fill(tmp_path: Path) -> dict[str, str]:
    """The files and the closed port the cases name (each test its own)."""
    (tmp_path / "capture.txt").write_text("03 a3 ff 88 ad\n02 8a bc c8\n")
    (tmp_path / "capture.bin").write_bytes(bytes.fromhex("03a3ff88ad028abcc8"))
    backup = tmp_path / "backup.json"
    backup.write_text(json.dumps({"format": "servobus.params", "version": 1,
                                  "protocol": "dyn232", "drive_id": 0,
                                  "params": {n: P.spec(n).default for n in P.DYN_PARAMS}}))
    return {"closed": str(free_port()), "tmp": str(tmp_path), "backup": str(backup),
            "hexfile": str(tmp_path / "capture.txt"), "binfile": str(tmp_path / "capture.bin")}


@pytest.fixture
def in_process(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
               ) -> Iterator[Any]:
    """Run ``main(args)`` as the console script would; give back its exit code and streams.

    main() quiets python-can's loggers for the process; they are put back afterwards so the
    other tests of this worker still see them.
    """
    saved = {name: (logging.getLogger(name).level, logging.getLogger(name).propagate)
             for name in QUIET_LOGGERS}

    def run(args: list[str], env: dict[str, str] | None = None) -> Outcome:
        monkeypatch.delenv(DEBUG_ENV, raising=False)
        for key, value in (env or {}).items():
            monkeypatch.setenv(key, value)
        monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b"")))  # as </dev/null
        capsys.readouterr()
        with pytest.raises(SystemExit) as exited:
            main(args)
        out = capsys.readouterr()
        code = exited.value.code
        return Outcome(code if isinstance(code, int) else 1, out.out, out.err)

    try:
        yield run
    finally:
        for name, (level, propagate) in saved.items():
            logging.getLogger(name).setLevel(level)
            logging.getLogger(name).propagate = propagate


def subprocess_run(args: list[str], env: dict[str, str] | None = None) -> Outcome:
    base = {k: v for k, v in os.environ.items() if k != DEBUG_ENV}
    proc = subprocess.run([*SERVOBUS, *args], capture_output=True, text=True,
                          timeout=CASE_TIMEOUT_S, env=base | (env or {}),
                          stdin=subprocess.DEVNULL)
    return Outcome(proc.returncode, proc.stdout, proc.stderr)


def check(case: Case, out: Outcome) -> None:
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert "Traceback" not in out.stderr
    assert out.code == case.code, out.stderr
    assert lines[0].startswith("error: ") and " - " in lines[0], lines[0]
    assert case.says in lines[0], lines[0]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_mistake_gives_one_line_and_its_exit_code(case: Case, fill: dict[str, str],
                                                   in_process: Any) -> None:
    check(case, in_process([a.format(**fill) for a in case.args], dict(case.env)))


@pytest.mark.slow
@pytest.mark.parametrize("case", [BY_ID[i] for i in END_TO_END], ids=END_TO_END)
def test_mistake_as_a_real_process(case: Case, fill: dict[str, str]) -> None:
    check(case, subprocess_run([a.format(**fill) for a in case.args], dict(case.env)))


def test_socketcand_with_nothing_listening_fails_fast(fill: dict[str, str], in_process: Any,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 7 measured 10.6 s: python-can's socketcand bus retried a dead address. The probe
    refuses at once, so python-can's bus is never opened (checked instead of a wall-clock
    figure, which would depend on the machine's load)."""
    import can

    opened: list[dict[str, Any]] = []

    def bus(**kwargs: Any) -> None:
        opened.append(kwargs)
        raise AssertionError("python-can's Bus was opened for a dead socketcand address")

    monkeypatch.setattr(can, "Bus", bus)
    case = BY_ID["dead-socketcand-status"]
    check(case, in_process([a.format(**fill) for a in case.args]))
    assert opened == []


@pytest.mark.slow
@pytest.mark.parametrize("how", ["flag", "env"])
def test_debug_adds_the_traceback(how: str) -> None:
    extra, env = (["--debug"], {}) if how == "flag" else ([], {DEBUG_ENV: "1"})
    proc = subprocess_run([*extra, "sniff", "--from-file", "/nonexistent/x.bin"], env)
    assert proc.code == EXIT_USAGE
    assert "Traceback" in proc.stderr
    assert proc.stderr.splitlines()[-1].startswith("error: cannot read /nonexistent/x.bin")
