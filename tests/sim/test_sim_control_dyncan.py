"""The control channel of `servobus sim dyncan`, through real sockets (socketcand + JSON
lines): a fault pushes Drive Error 0xEE and shows in the status byte; during the alarm
writes are ignored and reads answered (6.1); the 0x1C reset clears it; the CLI client."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator

import can
import pytest
from rig import wait_until
from subprocess_rig import read_line

from servobus.families.dmm.registers import ALARM_SHIFT, StatusBits
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyncan import codec as c
from servobus.sim.control_client import ControlClient

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
SAFETY_NET_S = "600"  # --duration: the fixture stops it; a loaded module takes minutes
F = c.Function
CLI = [sys.executable, "-m", "servobus"]


@pytest.fixture
def sim() -> Iterator[tuple[int, str]]:
    proc = subprocess.Popen(
        [*CLI, "sim", "dyncan", "--socketcand", "127.0.0.1:0", "--ids", "1,2", "--fast",
         "--control", "tcp://127.0.0.1:0", "--duration", SAFETY_NET_S],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0)
    try:
        can_port = int(read_line(proc, "listening on socketcand 127.0.0.1:").rsplit(":", 1)[1])
        url = read_line(proc, "control on tcp://127.0.0.1:").split(" ", 2)[2]
        yield can_port, url
    finally:
        proc.terminate()
        proc.wait(10)


class Host:
    def __init__(self, port: int) -> None:
        self.bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")

    def send(self, frame: c.Frame) -> None:
        ident, data = c.encode(frame)
        self.bus.send(can.Message(arbitration_id=ident, data=data, is_extended_id=False))

    def recv(self, ident: int, timeout: float = 2.0) -> c.Frame | None:
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            msg = self.bus.recv(left)
            if msg is not None and msg.arbitration_id == ident:
                return c.decode(msg.arbitration_id, msg.data)
        return None

    def ask(self, frame: c.Frame, timeout: float = 2.0) -> c.Frame | None:
        self.send(frame)
        return self.recv(c.arbitration_id(frame.drive_id, frame.function), timeout)

    def alarm_code(self, drive_id: int) -> int:
        reply = self.ask(c.request(drive_id, DmmFunction.READ_DRIVE_STATUS))
        assert reply is not None
        return (reply.data[0] & StatusBits.ALARM_MASK) >> ALARM_SHIFT


def test_6_1_a_fault_pushes_0xee_writes_are_ignored_reads_answered_reset_clears(
        sim: tuple[int, str]) -> None:
    port, url = sim
    host = Host(port)
    try:
        with ControlClient(url) as ctl:
            assert host.alarm_code(2) == 0  # the host's bus is live (rawmode)
            assert ctl.call("fault", 2, fault="over_voltage")["alarm_code"] == 5
            err = host.recv(c.arbitration_id(2, F.DRIVE_ERROR))
            assert err is not None and err.data == bytes((c.DriveErrorCode.ALARM,))
            assert host.alarm_code(2) == 5 and host.alarm_code(1) == 0
            host.send(c.request(2, F.SET_PARAM_GROUP1, fields=(99, 0, 0, 0)))
            group = host.ask(c.request(2, F.READ_PARAM_GROUP1))
            assert group is not None and group.fields()[0] != 99
            host.send(c.request(2, DmmFunction.GENERAL_READ, 0x1C))  # reset = power cycle
            assert host.alarm_code(2) == 0
            # powered off for a moment: the node answers nothing, then it is back
            ctl.call("power_cycle", 2, off_s=0.5)
            assert host.ask(c.request(2, DmmFunction.READ_DRIVE_STATUS), timeout=0.2) is None
            wait_until(lambda: host.ask(c.request(2, DmmFunction.READ_DRIVE_STATUS), timeout=0.1),
                       timeout=5, what="drive 2 back after the power cycle")
            assert host.alarm_code(2) == 0
    finally:
        host.bus.shutdown()


def test_cli_sim_control_commands_and_errors(sim: tuple[int, str]) -> None:
    _, url = sim

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*CLI, "sim", "control", "--to", url, *args],
                              capture_output=True, text=True, timeout=30)

    out = run("--id", "1", "analog", "2.5")
    assert out.returncode == 0, out.stderr
    out = run("--id", "1", "state", "--json")
    assert out.returncode == 0 and json.loads(out.stdout)["inputs"]["analog_v"] == 2.5
    out = run("--id", "1", "fault", "overheat", "--temperature-c", "95")
    assert out.returncode == 0 and "alarm: \"overheat\"" in out.stdout
    out = run("--id", "1", "outputs")
    assert "pins.8: \"low\"" in out.stdout
    out = run("state")  # two drives: the id is needed
    assert out.returncode == 2 and out.stderr.startswith("error: id is needed")
    out = run("--id", "1", "analog", "20")
    assert out.returncode == 2 and "outside -12..12" in out.stderr
    out = run("--id", "1", "send", '{"cmd": "ping"}')
    assert out.returncode == 0 and "ids: 1, 2" in out.stdout
    out = subprocess.run([*CLI, "sim", "control", "--to", "tcp://127.0.0.1:1", "ping"],
                         capture_output=True, text=True, timeout=30)
    assert out.returncode == 2 and "cannot reach the control channel" in out.stderr
