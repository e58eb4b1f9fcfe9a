"""``servobus hal`` in a real HAL session (halrun): siggen drives two position axes on
virtual drives in their own processes (a DMM drive on DYN232M, a YZ-AIM motor on EasyCan);
position-fb reaches the command, a fault injected through the simulator's control channel
raises fault and fault-reset clears it, and the component's end stops every axis. Then the
full LinuxCNC runs the rotary example's G-code on a virtual YZ-AIM motor, headless.

One file: HAL's shared memory is one per host, so these run one after the other."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from hal_rig import HalSession, needs_halrun, needs_linuxcnc, run_linuxcnc
from rig import free_port, wait_until
from subprocess_rig import read_line, stop_process

import servobus
from servobus.axis import Axis
from servobus.sim.control_client import ControlClient

pytestmark = [needs_halrun, pytest.mark.slow, pytest.mark.timeout(180)]

CELL = """\
name = "hal-cell"

[axes.x]
url = "dyn232+socket://127.0.0.1:{dyn232}"
id = 1
unit = "deg"
speed = 720.0
accel = 7200.0
hal = "position"

[axes.m]
url = "dyn232+socket://127.0.0.1:{dyn232}"
id = 2
unit = "mm"
per_rev = 5.0

[axes.c]
url = "easycan+socketcand://127.0.0.1:{can}"
id = 1
unit = "deg"
speed = 720.0
accel = 7200.0
hal = "position"
"""

HAL = """\
loadrt threads name1=servo period1=1000000
loadrt siggen num_chan=2
addf siggen.0.update servo
addf siggen.1.update servo
setp siggen.0.frequency 0
setp siggen.0.amplitude 45
setp siggen.1.frequency 20
loadusr -Wn servobus {servobus} hal --machine cell.toml --watchdog 2
net cmd siggen.0.sine => servobus.x.position-cmd servobus.c.position-cmd
net wd siggen.1.clock => servobus.watchdog
start
"""


def start(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "servobus", "sim", *args, "--fast",
                             "--duration", "300"],  # a safety net only
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture
def sims() -> Iterator[tuple[int, int, str]]:
    """(DYN232M port, socketcand port, control URL) of two virtual drives."""
    dyn232, can = free_port(), free_port()
    drive = start("dyn232", "--listen", f"tcp://127.0.0.1:{dyn232}", "--ids", "1,2",
                  "--control", "tcp://127.0.0.1:0")
    motor = start("easycan", "--socketcand", f"127.0.0.1:{can}", "--ids", "1")
    try:
        read_line(drive, "listening on")
        control = read_line(drive, "control on").split()[-1]
        read_line(motor, "listening on")
        yield dyn232, can, control
    finally:
        stop_process(drive)
        stop_process(motor)


EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "linuxcnc"


def at_rest(axis: Axis) -> bool:
    """Standing: not moving, speed 0, and the same position over 20 reads in a row."""
    if axis.status().moving or axis.speed() != 0:
        return False
    first = axis.position()
    return all(axis.position() == first for _ in range(20))


def follows(pins: dict[str, str], axis: str) -> bool:
    command = float(pins[f"servobus.{axis}.position-cmd"])
    return abs(command) > 3.0 and abs(float(pins[f"servobus.{axis}.position-fb"]) - command) < 3.0


def test_halrun_streams_faults_resets_and_stops(tmp_path: Path,
                                                sims: tuple[int, int, str]) -> None:
    dyn232, can, control = sims
    (tmp_path / "cell.toml").write_text(CELL.format(dyn232=dyn232, can=can))
    servobus_path = Path(sys.executable).parent / "servobus"
    (tmp_path / "cell.hal").write_text(HAL.format(servobus=servobus_path))
    session = HalSession(tmp_path / "cell.hal")
    outside = servobus.connect(f"easycan+socketcand://127.0.0.1:{can}", drive_id=1)
    try:
        # the watchdog fed (the thread runs) and both links up: no fault; then enable, and
        # siggen's sine starts from 0 where the motors stand (LinuxCNC's joints start at
        # their feedback)
        wait_until(lambda: session.pins("servobus").get("servobus.fault") == "FALSE",
                   timeout=30, poll=0.05, what="no fault" + session.output())
        session.halcmd("setp", "servobus.x.enable", "1")
        session.halcmd("setp", "servobus.c.enable", "1")
        wait_until(lambda: (p := session.pins("servobus"))["servobus.x.enabled"] == "TRUE"
                   and p["servobus.c.enabled"] == "TRUE", timeout=30, poll=0.05,
                   what="servo on")
        session.halcmd("setp", "siggen.0.frequency", "0.1")
        wait_until(lambda: (p := session.pins("servobus")) and follows(p, "x")
                   and follows(p, "c"), timeout=60, poll=0.05,
                   what="position-fb reaching position-cmd" + session.output())

        with ControlClient(control) as drives:  # a surge trips alarm 5 on both DMM drives
            drives.call("fault", 1, fault="over_voltage", seconds=0.01)
            drives.call("fault", 2, fault="over_voltage", seconds=0.01)
        pins = wait_until(lambda: (p := session.pins("servobus"))["servobus.x.fault"] == "TRUE"
                          and p["servobus.m.fault"] == "TRUE" and p, timeout=30, poll=0.05,
                          what="fault raised on x (position) and m (monitor)")
        assert pins["servobus.fault"] == "TRUE" and pins["servobus.x.alarm-code"] == "5"
        assert pins["servobus.m.alarm-code"] == "5" and pins["servobus.c.fault"] == "FALSE"
        session.halcmd("setp", "servobus.x.fault-reset", "1")
        session.halcmd("setp", "servobus.m.fault-reset", "1")
        wait_until(lambda: (p := session.pins("servobus"))["servobus.x.fault"] == "FALSE"
                   and p["servobus.m.fault"] == "FALSE" and p["servobus.fault"] == "FALSE",
                   timeout=30, poll=0.05, what="fault-reset clearing it" + session.output())

        before = outside.position()  # c still streams siggen's sine
        wait_until(lambda: outside.position() != before, timeout=30, what="c streaming")
        session.halcmd("setp", "siggen.0.frequency", "0")  # the command holds (see SIGKILL)
        session.halcmd("unloadusr", "servobus")  # SIGTERM, as halrun's exit and LinuxCNC's
        wait_until(lambda: not session.pins("servobus"), timeout=30, what="component gone")
        wait_until(lambda: at_rest(outside), timeout=30, what="c at rest")
        with ControlClient(control) as drive:
            state = drive.call("state", 1)
        assert not state["motion_busy"] and abs(state["speed_rpm"]) < 1
        log = session.log.read_text()
        assert "every position axis stopped" in log
        # EasyCan streams its 2 ms cache, DYN232M target updates (docs/linuxcnc.md)
        assert "axis c: enabled, streaming position-cmd every cycle of the drive" in log, log
        assert "axis x: enabled, streaming position-cmd as target updates" in log, log

        # SIGKILL: nothing can stop the motor; it rests at the last position it was sent
        session.loadusr("-Wn", "servobus", str(servobus_path), "hal", "--machine", "cell.toml",
                        "--watchdog", "2")
        session.halcmd("net", "cmd", "=>", "servobus.c.position-cmd")
        session.halcmd("net", "wd", "=>", "servobus.watchdog")
        wait_until(lambda: session.pins("servobus").get("servobus.fault") == "FALSE",
                   timeout=60, poll=0.05, what="reloaded, no fault" + session.output())
        session.halcmd("setp", "servobus.c.enable", "1")
        wait_until(lambda: "axis c: enabled, streaming" in session.log.read_text()[len(log):],
                   timeout=30, what="c streaming again" + session.output())
        session.halcmd("setp", "siggen.0.frequency", "0.1")
        before = outside.position()
        wait_until(lambda: outside.position() != before, timeout=30, what="c moving")
        os.kill(session.user_pid("servobus"), signal.SIGKILL)
        wait_until(lambda: at_rest(outside), timeout=30, what="c at rest after SIGKILL")
    finally:
        outside.close()
        session.close()


@needs_linuxcnc
def test_linuxcnc_runs_the_rotary_example_on_a_virtual_motor(tmp_path: Path) -> None:
    can = free_port()
    motor = start("easycan", "--socketcand", f"127.0.0.1:{can}", "--ids", "1")
    try:
        read_line(motor, "listening on")
        config = tmp_path / "rotary"
        shutil.copytree(EXAMPLES / "rotary", config)
        toml = config / "rotary.toml"
        toml.write_text(toml.read_text().replace(
            'url = "sim://easycan"', f'url = "easycan+socketcand://127.0.0.1:{can}"'))
        ini = config / "rotary.ini"
        # headless; and the margins of a loaded 2-core host, as --watchdog 2 above: a
        # servo thread woken late by 1 s trips 0.5 s and the example's following error
        ini.write_text(ini.read_text().replace("DISPLAY = axis", "DISPLAY = ./run_program.py")
                       .replace("WATCHDOG = 0.5", "WATCHDOG = 2")
                       .replace("FERROR = 20", "FERROR = 180")
                       .replace("MIN_FERROR = 10", "MIN_FERROR = 90"))
        assert all(line in ini.read_text().splitlines() for line in (
            "DISPLAY = ./run_program.py", "WATCHDOG = 2", "FERROR = 180", "MIN_FERROR = 90"))
        output = run_linuxcnc(ini)
        done = re.search(r"run_program: done at joint 0 (-?[\d.]+)", output)
        assert done is not None and abs(float(done[1]) - 135.0) < 0.05, output
        assert "every position axis stopped" in output, output
        with servobus.connect(f"easycan+socketcand://127.0.0.1:{can}", drive_id=1) as outside:
            angle = outside.position() * 360 / outside.counts_per_rev
        assert abs(angle - 135.0) < 0.1, (angle, output)  # the program's last line: A135
    finally:
        stop_process(motor)
