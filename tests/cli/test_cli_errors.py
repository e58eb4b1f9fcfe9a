"""Every mistake a user makes at the terminal ends with one stderr line and a documented code.

Table-driven, in real processes (``python -m servobus``): the property is about what the
terminal shows, including anything printed at interpreter exit. The cases run concurrently
(a few at a time) so the table stays fast; each case is still its own test.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import pytest

from servobus.cli.failures import EXIT_FAULT, EXIT_USAGE
from servobus.families.dmm import params as P

SERVOBUS = [sys.executable, "-m", "servobus"]
CASE_TIMEOUT_S = 20.0


def closed_port() -> int:
    """A local TCP port nothing listens on (bound once, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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
    seconds: float


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


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Outcome]]:
    """Run every case once (4 at a time); each test then checks its own."""
    tmp = tmp_path_factory.mktemp("cli-errors")
    (tmp / "capture.txt").write_text("03 a3 ff 88 ad\n02 8a bc c8\n")
    (tmp / "capture.bin").write_bytes(bytes.fromhex("03a3ff88ad028abcc8"))
    backup = tmp / "backup.json"
    backup.write_text(json.dumps({"format": "servobus.params", "version": 1,
                                  "protocol": "dyn232", "drive_id": 0,
                                  "params": {n: P.spec(n).default for n in P.DYN_PARAMS}}))
    fill = {"closed": str(closed_port()), "tmp": str(tmp), "backup": str(backup),
            "hexfile": str(tmp / "capture.txt"), "binfile": str(tmp / "capture.bin")}

    def run(case: Case) -> tuple[str, Outcome]:
        args = [a.format(**fill) for a in case.args]
        env = {k: v for k, v in os.environ.items() if k != "SERVOBUS_DEBUG"} | dict(case.env)
        t0 = time.monotonic()
        proc = subprocess.run([*SERVOBUS, *args], capture_output=True, text=True,
                              timeout=CASE_TIMEOUT_S, env=env, stdin=subprocess.DEVNULL)
        return case.id, Outcome(proc.returncode, proc.stdout, proc.stderr,
                                time.monotonic() - t0)

    with ThreadPoolExecutor(max_workers=4) as pool:
        yield dict(pool.map(run, CASES))


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_mistake_gives_one_line_and_its_exit_code(case: Case,
                                                   outcomes: dict[str, Outcome]) -> None:
    out = outcomes[case.id]
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert "Traceback" not in out.stderr
    assert out.code == case.code, out.stderr
    assert lines[0].startswith("error: ") and " - " in lines[0], lines[0]
    assert case.says in lines[0], lines[0]


def test_socketcand_with_nothing_listening_fails_fast(outcomes: dict[str, Outcome]) -> None:
    """Issue 7 measured 10.6 s (python-can's retry loop); the probe refuses at once."""
    assert outcomes["dead-socketcand-status"].seconds < 3.0


def test_debug_adds_the_traceback() -> None:
    for extra, env in ((["--debug"], {}), ([], {"SERVOBUS_DEBUG": "1"})):
        proc = subprocess.run([*SERVOBUS, *extra, "sniff", "--from-file", "/nonexistent/x.bin"],
                              capture_output=True, text=True, timeout=CASE_TIMEOUT_S,
                              env=os.environ | env)
        assert proc.returncode == EXIT_USAGE
        assert "Traceback" in proc.stderr
        assert proc.stderr.splitlines()[-1].startswith("error: cannot read /nonexistent/x.bin")
