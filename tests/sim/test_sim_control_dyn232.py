"""The control channel of `servobus sim dyn232`, through real sockets: the host program talks
DYN232M on the line, the test bench works JP3 and injects faults on the control channel.

Analog speed mode reaches the manual's rpm (4.2), a pulse train moves the shaft by the gear
ratio (4.1), each fault trips its alarm code in the status byte (7.3) and clears as 6.1 says
(power cycle, here the General_Read 0x1C reset or the channel's power_cycle)."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rig import wait_until
from subprocess_rig import read_line

from servobus.cli.main import main
from servobus.families.dmm.registers import ALARM_SHIFT, StatusBits
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c
from servobus.sim.control_client import ControlClient
from servobus.sim.core.loads import PRESETS
from servobus.sim.dmm.control import ControlError

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
H, GR = c.HostFunction, c.GeneralReadSelector
SERVER_S = 600.0  # a safety net (the fixture stops it): a loaded module takes minutes


class Bench:
    """A `servobus sim dyn232 --fast` process: the DYN232M line and the control channel."""

    def __init__(self, *ids: int) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "servobus", "sim", "dyn232", "--fast", "--ids",
             ",".join(map(str, ids)), "--control", "tcp://127.0.0.1:0",
             "--duration", str(SERVER_S)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0)
        line_port = int(read_line(self.proc, "listening on tcp://127.0.0.1:").rsplit(":", 1)[1])
        self.control_url = read_line(self.proc, "control on tcp://127.0.0.1:").split(" ", 2)[2]
        self.sock = socket.create_connection(("127.0.0.1", line_port), timeout=2)
        self.control = ControlClient(self.control_url)

    def close(self) -> None:
        self.control.close()
        self.sock.close()
        self.proc.terminate()
        self.proc.wait(10)

    # ---- the host program's side: DYN232M packets
    def send(self, drive_id: int, fn: H, value: int = 0) -> None:
        self.sock.sendall(c.encode(drive_id, fn, value))

    def ask(self, drive_id: int, fn: H, value: int = 0, timeout: float = 1.0) -> int | None:
        """One read; its reply value, or None when nothing came back within ``timeout``."""
        self.send(drive_id, fn, value)
        framer, got = c.Framer(), []
        deadline = time.monotonic() + timeout
        while not got and (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(64)
            except TimeoutError:
                break
            got = [e for e in framer.feed(data) if isinstance(e, c.Packet)]
        return got[0].reply_value() if got else None

    def status(self, drive_id: int = 1) -> int:
        value = self.ask(drive_id, DF.READ_DRIVE_STATUS)
        assert value is not None, "no status reply"
        return value

    def alarm_code(self, drive_id: int = 1) -> int:
        return (self.status(drive_id) & StatusBits.ALARM_MASK) >> ALARM_SHIFT

    def read(self, selector: GR, drive_id: int = 1) -> int:
        value = self.ask(drive_id, DF.GENERAL_READ, selector)
        assert value is not None
        return value

    # ---- the test bench's side: the control channel
    def ctl(self, cmd: str, drive_id: int = 1, **args: Any) -> dict[str, Any]:
        return self.control.call(cmd, drive_id, **args)


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = Bench(1)
    try:
        yield b
    finally:
        b.close()


def test_4_2_analog_speed_mode_reaches_the_manuals_rpm(bench: Bench) -> None:
    bench.send(1, DF.SET_DRIVE_CONFIG, 0x08)  # b4 b3 = 1: speed servo
    for volts, rpm in ((5.0, 3000), (-3.0, -1800)):  # the table of 4.2
        bench.ctl("analog", volts=volts)
        wait_until(lambda rpm=rpm: abs(bench.read(GR.SPEED) - rpm) <= 0.01 * abs(rpm),
                   timeout=5, what=f"{rpm} rpm")
    assert bench.status() & StatusBits.JP3_PIN2 == 0  # -3 V: pin 2 low (status b6)
    bench.ctl("analog", volts=5.0)
    wait_until(lambda: bench.status() & StatusBits.JP3_PIN2, timeout=2, what="b6 high")


def test_4_1_a_pulse_train_moves_the_shaft_by_the_gear_ratio(bench: Bench) -> None:
    bench.send(1, DF.SET_DRIVE_CONFIG, 0x02)  # Pulse/Dir
    bench.send(1, H.SET_GEAR_NUMBER, 500)  # 4 x 500 = 2,000 pulses per revolution
    reply = bench.ctl("pulses", count=2000, rate=20_000)  # 0.1 s
    assert reply["taken"] == 2000 and reply["format"] == "pulse_dir"
    wait_until(lambda: bench.read(GR.POSITION) == 65_536, timeout=5, what="one revolution")
    bench.send(1, DF.SET_DRIVE_CONFIG, 0x01)  # CW/CCW
    assert bench.ctl("pulses", count=-500, seconds=0.05)["format"] == "cw_ccw"
    wait_until(lambda: bench.read(GR.POSITION) == 65_536 - 16_384, timeout=5, what="-1/4 rev")
    # a train in a format the drive does not decode: what that decoder sees (miswired)
    assert bench.ctl("pulses", count=100, format="ab")["taken"] == 0
    bench.send(1, DF.SET_DRIVE_CONFIG, 0x00)  # RS232 mode: pulses are ignored
    assert bench.ctl("pulses", count=100)["ignored"] is True


@pytest.mark.parametrize(("fault", "args", "code"), [
    ("over_current", {}, 2),
    ("over_voltage", {}, 5),
    ("overheat", {"temperature_c": 86.0}, 3),
])
def test_6_1_each_fault_trips_its_alarm_code_and_a_power_cycle_clears_it(
        bench: Bench, fault: str, args: dict[str, Any], code: int) -> None:
    assert bench.alarm_code() == 0
    bench.ctl("fault", fault=fault, **args)
    assert bench.alarm_code() == code
    assert bench.status() & StatusBits.SERVO_FREE  # 6.1: the motor is freed
    outputs = bench.ctl("outputs")
    assert outputs["alarm"] and outputs["pins"]["8"] == "low"
    bench.send(1, H.SET_MAIN_GAIN, 77)  # 6.1: ignored, not stored
    assert bench.ask(1, H.READ_MAIN_GAIN) != 77
    bench.send(1, DF.GENERAL_READ, GR.ENABLE)  # ENA / enable do not clear it
    assert bench.alarm_code() == code
    # Until the cause is gone: the surge is over and the power stage has cooled below the
    # trip level (the drive's own state says so).
    wait_until(lambda: (st := bench.ctl("state"))["temperature_c"] < 85
               and st["bus_voltage"] <= 80, timeout=30, what="the cause gone")
    bench.send(1, DF.GENERAL_READ, GR.RESET)  # the power cycle of 6.1
    assert bench.alarm_code() == 0
    assert bench.status() & StatusBits.SERVO_FREE == 0


def test_6_1_an_overheated_drive_trips_again_until_it_has_cooled(bench: Bench) -> None:
    bench.ctl("fault", fault="overheat", temperature_c=120.0)
    assert bench.alarm_code() == 3
    assert bench.ctl("state")["temperature_c"] > 85
    bench.send(1, DF.GENERAL_READ, GR.RESET)
    wait_until(lambda: bench.alarm_code() == 3, timeout=2, what="trips again while hot")
    wait_until(lambda: bench.ctl("state")["temperature_c"] < 84, timeout=30, what="cooled")
    bench.ctl("power_cycle")
    assert bench.alarm_code() == 0


def test_6_1_an_encoder_fault_trips_lost_phase_until_it_is_cleared(bench: Bench) -> None:
    bench.ctl("fault", fault="lost_phase", cause="encoder")
    assert bench.alarm_code() == 1
    bench.send(1, DF.GENERAL_READ, GR.RESET)
    wait_until(lambda: bench.alarm_code() == 1, timeout=2, what="the fault is still there")
    bench.ctl("clear")
    bench.send(1, DF.GENERAL_READ, GR.RESET)
    assert bench.alarm_code() == 0


def test_7_3_a_blocked_shaft_trips_lost_phase_when_the_motor_must_move(bench: Bench) -> None:
    bench.ctl("fault", fault="lost_phase", cause="blocked")
    assert bench.alarm_code() == 0  # at rest nothing is wrong yet
    bench.send(1, DF.GO_RELATIVE_POS, 4096)  # 90 deg: >= 90 deg for 2 s (4.1)
    wait_until(lambda: bench.alarm_code() == 1, timeout=6, what="lost phase")
    state = bench.ctl("state")
    assert state["alarm"] == "lost_phase" and state["servo"] == "free"


def test_load_step_inertia_and_following_error_are_visible_in_the_state(bench: Bench) -> None:
    bench.ctl("fault", fault="inertia", kgm2=5e-4)
    bench.ctl("fault", fault="load_step", torque_nm=1.0)
    wait_until(lambda: abs(bench.ctl("state")["current_a"] + 1.0 / 0.36) < 0.1, timeout=3,
               what="the servo holds the load torque")
    state = bench.ctl("state")
    assert state["world"]["load_inertia_kgm2"] == 5e-4 and state["world"]["load_torque_nm"] == 1
    bench.send(1, DF.TURN_CONST_SPEED, 1000)
    wait_until(lambda: abs(bench.ctl("state")["speed_rpm"] - 1000) < 20, timeout=3,
               what="1000 rpm")
    state = bench.ctl("state")
    assert state["following_error"] != 0 and state["reference"] > state["position"] - 1000
    assert state["following_error_deg"] == pytest.approx(state["following_error"] * 360 / 65536,
                                                         abs=1e-3)


def test_servobus_sim_control_load_sets_the_load_to_tune_on(bench: Bench) -> None:
    with pytest.raises(SystemExit) as done:
        main(["sim", "control", "--to", bench.control_url, "--id", "1", "load", "--load",
              "belt", "--inertia", "10", "--load-torque", "0.2"])
    assert done.value.code in (0, None)
    mechanics = bench.ctl("load")["mechanics"]  # no keys: changes nothing, says the load
    assert (mechanics["inertia"], mechanics["resonance"], mechanics["load_torque"]) == (
        10.0, PRESETS["belt"].resonance, 0.2)


def test_a_supply_dip_below_24_v_powers_the_drive_off_and_on(bench: Bench) -> None:
    bench.ctl("fault", fault="over_current")
    bench.ctl("fault", fault="supply_dip", volts=10.0, seconds=0.4)
    assert bench.ask(1, DF.READ_DRIVE_STATUS, timeout=0.1) is None  # off: no answer
    outputs = bench.ctl("outputs")
    assert not outputs["powered"] and set(outputs["pins"].values()) == {"high"}
    wait_until(lambda: bench.ask(1, DF.READ_DRIVE_STATUS, timeout=0.1) is not None, timeout=5,
               what="back on")
    assert bench.alarm_code() == 0  # a brown-out is a power cycle
    bench.ctl("fault", fault="supply_dip", volts=30.0, seconds=0.2)  # above 24 V: running
    assert bench.ctl("state")["bus_voltage"] == 30.0 and bench.alarm_code() == 0


def test_ena_frees_the_motor_and_an_unknown_id_is_refused(bench: Bench) -> None:
    bench.ctl("ena", enabled=False)
    assert bench.status() & StatusBits.SERVO_FREE
    bench.ctl("ena", enabled=True)
    assert bench.status() & StatusBits.SERVO_FREE == 0
    with pytest.raises(ControlError) as exc:
        bench.ctl("state", drive_id=7)
    assert exc.value.kind == "unknown_id"
