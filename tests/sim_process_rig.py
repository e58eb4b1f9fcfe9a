"""Virtual drives in their own processes, one per protocol, on a fixed free port: killed
and started again on the same port, as a drive that loses power and boots (issue 29's
recovery tests of the machine and of the gateway).

``SIMS`` maps each protocol to its ``servobus sim`` arguments and the drive URL that
reaches it ({port} is the port); ``start_sim`` starts one and returns once it listens;
the ``procs`` fixture stops every process a test started (a test module imports it:
``from sim_process_rig import procs as procs``).
"""

from __future__ import annotations

import subprocess
import sys
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
    return SIMS[protocol][1].format(port=port)


def start_sim(protocol: str, port: int) -> subprocess.Popen[str]:
    """``servobus sim <protocol>`` on ``port``, once it says it is listening."""
    args = [a.format(port=port) for a in SIMS[protocol][0]]
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", *args,
                             "--duration", "300"],  # a safety net only
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while "listening on" not in read_line(proc):
            pass
    except BaseException:
        stop_process(proc)
        raise
    return proc


@pytest.fixture
def procs() -> Iterator[list[subprocess.Popen[str]]]:
    """The processes a test started (it appends them); each is stopped at its end."""
    started: list[subprocess.Popen[str]] = []
    yield started
    for proc in started:
        stop_process(proc)
