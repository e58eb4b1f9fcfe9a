"""pymodbus, the Modbus library users know, as an independent client of the virtual line:
its RTU framer over TCP and over a pseudo-terminal, reading and writing the YZ-AIM register
map of ``servobus sim modbus`` (the example of docs/modbus.md)."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from rig import wait_until

from servobus.cli.main import cli
from servobus.families.yzaim import registers as Y
from servobus.sim.control_client import ControlClient

pymodbus = pytest.importorskip("pymodbus")
from pymodbus import FramerType  # noqa: E402
from pymodbus.client import ModbusSerialClient, ModbusTcpClient  # noqa: E402
from pymodbus.exceptions import ModbusException  # noqa: E402

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow]
INT32 = ModbusTcpClient.DATATYPE.INT32
R = Y.BY_NAME
ABS = Y.PAIR_BY_NAME["absolute_position"].low


def _start(*args: str) -> tuple[subprocess.Popen[str], list[str]]:
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "modbus", *args,
                             "--duration", "50"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    lines = [proc.stdout.readline().strip()]
    return proc, lines


@pytest.fixture
def tcp_line() -> Iterator[tuple[str, int]]:
    proc, lines = _start("--listen", "tcp://127.0.0.1:0", "--ids", "1,2")
    try:
        assert lines[0].startswith("listening on tcp://"), lines
        host, port = lines[0].split("tcp://", 1)[1].rsplit(":", 1)
        yield host, int(port)
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.fixture
def client(tcp_line: tuple[str, int]) -> Iterator[ModbusTcpClient]:
    host, port = tcp_line
    c = ModbusTcpClient(host, port=port, framer=FramerType.RTU, timeout=1, retries=0)
    assert c.connect()
    try:
        yield c
    finally:
        c.close()


def _until(check: Callable[[], Any], timeout: float = 10.0) -> Any:
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.05)  # the polling helper's own short sleep


def test_the_whole_register_map_reads_big_endian(client: ModbusTcpClient) -> None:
    rr = client.read_holding_registers(0x00, count=Y.REGISTER_COUNT, device_id=1)
    assert not rr.isError()
    regs = rr.registers
    assert len(regs) == 30
    assert regs[R["target_speed"].address] == 1000
    assert regs[R["acceleration"].address] == 10000
    assert regs[R["device_address"].address] == 1
    assert regs[R["supply_voltage"].address] == 30 * 327  # 57AIM30C: 24..36 V, 327 per volt
    assert client.read_holding_registers(R["device_address"].address,
                                         device_id=2).registers == [2]


def test_write_single_and_a_32_bit_move_low_word_first(client: ModbusTcpClient) -> None:
    assert not client.write_register(R["target_speed"].address, 1500, device_id=1).isError()
    assert client.read_holding_registers(R["target_speed"].address,
                                         device_id=1).registers == [1500]
    words = client.convert_to_registers(40000, INT32, word_order="little")
    assert words == [40000, 0]  # low word first (manual 5.4)
    assert not client.write_registers(ABS, words, device_id=1).isError()

    def position() -> int:
        regs = client.read_holding_registers(ABS, count=2, device_id=1).registers
        return int(client.convert_from_registers(regs, INT32, word_order="little"))

    assert abs(_until(lambda: abs(position() - 40000) <= 10 and position()) - 40000) <= 10
    back = client.convert_to_registers(-20000, INT32, word_order="little")
    client.write_registers(ABS, back, device_id=1)
    assert _until(lambda: abs(position() + 20000) <= 10)
    assert client.read_holding_registers(R["target_speed"].address,
                                         device_id=2).registers == [1000]  # id 2 untouched


def test_exception_replies(client: ModbusTcpClient) -> None:
    rr = client.read_holding_registers(0x1E, device_id=1)
    assert rr.isError() and rr.exception_code == 2  # ILLEGAL_DATA_ADDRESS
    wr = client.write_register(R["target_speed"].address, 5000, device_id=1)
    assert wr.isError() and wr.exception_code == 3  # ILLEGAL_DATA_VALUE
    wr = client.write_register(R["motor_speed"].address, 1, device_id=1)
    assert wr.isError() and wr.exception_code == 2  # read-only


def test_an_absent_address_is_silent(tcp_line: tuple[str, int]) -> None:
    host, port = tcp_line
    c = ModbusTcpClient(host, port=port, framer=FramerType.RTU, timeout=0.3, retries=0)
    assert c.connect()
    try:
        t0 = time.monotonic()
        with pytest.raises(ModbusException):
            c.read_holding_registers(0, device_id=9)
        assert time.monotonic() - t0 >= 0.3
    finally:
        c.close()


def test_broadcast_write(client: ModbusTcpClient) -> None:
    client.write_register(R["acceleration"].address, 20000, device_id=0,
                          no_response_expected=True)
    for device in (1, 2):
        assert _until(lambda d=device: client.read_holding_registers(
            R["acceleration"].address, device_id=d).registers == [20000])


def test_rtu_over_a_pseudo_terminal() -> None:
    proc, lines = _start("--pty", "--ids", "3")
    try:
        assert lines[0].startswith("pty /dev/"), lines
        path = lines[0].split(" ", 1)[1]
        c = ModbusSerialClient(path, framer=FramerType.RTU, baudrate=19200, timeout=1,
                               retries=1)
        assert c.connect()
        try:
            assert c.read_holding_registers(R["device_address"].address,
                                            device_id=3).registers == [3]
            assert not c.write_register(R["target_speed"].address, 750, device_id=3).isError()
            assert c.read_holding_registers(R["target_speed"].address,
                                            device_id=3).registers == [750]
        finally:
            c.close()
    finally:
        proc.terminate()
        proc.wait(10)


def test_state_file_keeps_a_multi_turn_position_across_a_restart(tmp_path: Path) -> None:
    """1: "communication mode: power-off record position": the 57AIM's multi-turn position
    survives a restart of ``sim modbus --state`` as it does for ``sim easycan`` (issue 34:
    the motor came back at 0). Written and read by pymodbus, the simulator SIGTERMed."""
    state = str(tmp_path / "motors.json")
    target = 3 * Y.COUNTS_PER_REV + 1234

    def position(c: ModbusTcpClient) -> int:
        regs = c.read_holding_registers(ABS, count=2, device_id=3).registers
        return int(c.convert_from_registers(regs, INT32, word_order="little"))

    def run(check: Callable[[ModbusTcpClient], int]) -> int:
        proc, lines = _start("--ids", "3", "--fast", "--state", state)
        try:
            assert lines[0].startswith("listening on tcp://"), lines
            host, port = lines[0].split("tcp://", 1)[1].rsplit(":", 1)
            c = ModbusTcpClient(host, port=int(port), framer=FramerType.RTU, timeout=2,
                                retries=1)
            assert c.connect()
            try:
                return check(c)
            finally:
                c.close()
        finally:
            proc.terminate()
            assert proc.wait(10) == 0

    def move(c: ModbusTcpClient) -> int:
        words = c.convert_to_registers(target, INT32, word_order="little")
        assert not c.write_registers(ABS, words, device_id=3).isError()
        wait_until(lambda: abs(position(c) - target) <= 10, timeout=20.0, what="the move")
        # at rest on its target: two equal reads in a row can catch the P loop closing the
        # last count (docs/tuning.md), so wait for the target itself
        wait_until(lambda: position(c) == target, timeout=20.0, what="the motor at rest")
        return position(c)

    before = run(move)
    assert run(position) == before


def test_the_control_channel_injects_faults_pymodbus_reads() -> None:
    """``--control`` as on ``sim dyn232``: a flat battery (warning 0x13, the motor keeps
    running) through the control client, cleared and a blocked shaft injected through
    ``servobus sim control`` (stall 0x14 after 0x18's units digit, 1 s here), each read by
    pymodbus from 0x0E."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "modbus", "--ids", "3",
                             "--fast", "--control", "tcp://127.0.0.1:0", "--duration", "50"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        listening, control_line = proc.stdout.readline(), proc.stdout.readline()
        host, port = listening.strip().split("tcp://", 1)[1].rsplit(":", 1)
        assert control_line.startswith("control on tcp://127.0.0.1:"), control_line
        url = control_line.strip().split(" ", 2)[2]
        c = ModbusTcpClient(host, port=int(port), framer=FramerType.RTU, timeout=2, retries=1)
        assert c.connect()
        try:
            def alarm() -> int:
                return int(c.read_holding_registers(R["alarm_code"].address,
                                                    device_id=3).registers[0])

            with ControlClient(url) as control:
                assert control.call("fault", fault="battery")["alarm_code"] == 0x13
                assert alarm() == 0x13
            ok = CliRunner().invoke(cli, ["sim", "control", "--to", url, "battery", "ok"])
            assert ok.exit_code == 0 and 'alarm: "none"' in ok.output, ok.output
            assert alarm() == 0
            assert not c.write_register(R["standstill_max_output"].address, 301,
                                        device_id=3).isError()
            stall = CliRunner().invoke(cli, ["sim", "control", "--to", url, "fault", "stall"])
            assert stall.exit_code == 0 and 'fault: "stall"' in stall.output, stall.output
            words = c.convert_to_registers(Y.COUNTS_PER_REV, INT32, word_order="little")
            assert not c.write_registers(ABS, words, device_id=3).isError()
            wait_until(lambda: alarm() == 0x14, timeout=20.0, what="stall 0x14")
        finally:
            c.close()
    finally:
        proc.terminate()
        proc.wait(10)
