"""Virtual drives in their own processes (``servobus sim ... --listen``), for tests that kill
one and start it again on the same port: the machine's recovery (issue 29) and the GUI's
offline state. ``procs`` is a fixture: a test module imports it by name."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator

import pytest
from subprocess_rig import read_line, stop_process

#: protocol -> (servobus sim arguments, drive URL); {port} is the fixed free port.
SIMS = {
    "dyn232": (["dyn232", "--listen", "tcp://127.0.0.1:{port}", "--ids", "1", "--fast"],
               "dyn232+socket://127.0.0.1:{port}"),
    "dyncan": (["dyncan", "--socketcand", "127.0.0.1:{port}", "--ids", "1"],
               "dyncan+socketcand://127.0.0.1:{port}"),
    "easycan": (["easycan", "--socketcand", "127.0.0.1:{port}", "--ids", "1"],
                "easycan+socketcand://127.0.0.1:{port}"),
    "enip": (["enip", "--tcp-port", "{port}", "--udp-port", "0"], "enip://127.0.0.1:{port}"),
    "modbus": (["modbus", "--listen", "tcp://127.0.0.1:{port}", "--ids", "1"],
               "modbus+socket://127.0.0.1:{port}"),
}


def sim_url(protocol: str, port: int) -> str:
    """The drive URL of the virtual drive ``start_sim(protocol, port)`` serves."""
    return SIMS[protocol][1].format(port=port)


#: How long a virtual drive may take to say it listens. Generous: a Python start and
#: servobus's imports are about 1 s of CPU, and took over 20 s of wall time (read_line's
#: default) beside two CPU-bound processes with other starts at once (test_gateway_restart
#: starts five at once: its set-up failed so in 2 of 4 runs).
START_S = 90.0


def start_sim(protocol: str, port: int) -> subprocess.Popen[str]:
    """``servobus sim PROTOCOL`` on ``port``, once it says it listens."""
    args = [a.format(port=port) for a in SIMS[protocol][0]]
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", *args,
                             "--duration", "300"],  # a safety net only
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + START_S
        while "listening on" not in read_line(proc, timeout=max(0.0, end - time.monotonic())):
            pass
    except BaseException:
        stop_process(proc)
        raise
    return proc


@pytest.fixture
def procs() -> Iterator[list[subprocess.Popen[str]]]:
    """Processes a test starts (append them): stopped at the end, whatever happened."""
    started: list[subprocess.Popen[str]] = []
    yield started
    for proc in started:
        stop_process(proc)
