"""`servobus sim enip --control`: the control channel reaches the virtual DYN5 (issue 13: a
control channel on every virtual-drive server), seen through a real enip:// client."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import pytest
from subprocess_rig import read_line

from servobus import connect
from servobus.errors import DriveAlarm
from servobus.sim.control_client import ControlClient

pytestmark = pytest.mark.timeout(60)
CLI = [sys.executable, "-m", "servobus"]


@pytest.fixture
def sim() -> Iterator[tuple[str, str]]:
    proc = subprocess.Popen(
        [*CLI, "sim", "enip", "--tcp-port", "0", "--udp-port", "0",
         "--control", "tcp://127.0.0.1:0", "--duration", "50"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0)
    try:
        listening = read_line(proc, "listening on enip://127.0.0.1:")
        url = listening.split(" ", 3)[2]  # enip://127.0.0.1:PORT
        control = read_line(proc, "control on tcp://127.0.0.1:").split(" ", 2)[2]
        yield url, control
    finally:
        proc.terminate()
        proc.wait(10)


def test_a_fault_set_over_the_control_channel_shows_on_the_drive(sim: tuple[str, str]) -> None:
    url, control = sim
    with connect(url) as axis, ControlClient(control) as ctl:
        assert axis.status().alarm_code == 0
        assert ctl.call("fault", axis.drive_id, fault="over_current")["alarm_code"] == 2
        st = axis.status()
        assert st.alarm_code == 2 and st.alarm_latched
        with pytest.raises(DriveAlarm):
            axis.wait_idle(timeout=1)
        state = ctl.call("state", axis.drive_id)
        assert "following_error" in state or "reference" in state
