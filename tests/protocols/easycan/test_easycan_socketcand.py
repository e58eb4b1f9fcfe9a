"""EasyCan across processes: ``servobus sim easycan`` over socketcand, python-can's own
socketcand client raw, ``connect()`` with an easycan+socketcand URL, and the CLI."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from servobus.axis import connect
from servobus.families import yzaim as Y
from servobus.protocols.easycan import codec
from servobus.protocols.easycan.messages import PositionReply, ReadReply, ReadRequest

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
SERVER_S = 600.0  # a safety net (the fixture stops it): a loaded module takes minutes
SERVOBUS = [sys.executable, "-m", "servobus"]


def start_server(*extra: str) -> tuple[subprocess.Popen[str], int]:
    proc = subprocess.Popen(
        [*SERVOBUS, "sim", "easycan", "--socketcand", "127.0.0.1:0", *extra,
         "--duration", str(SERVER_S)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith("listening on socketcand 127.0.0.1:"):
        proc.kill()
        raise AssertionError(f"{line!r} {proc.communicate()[1]}")
    return proc, int(line.rsplit(":", 1)[1])


@pytest.fixture(scope="module")
def server() -> Iterator[int]:
    proc, port = start_server("--ids", "1,2", "--fast")
    try:
        yield port
    finally:
        proc.terminate()
        proc.wait(10)


def recv_reply(bus: can.BusABC, timeout: float = 2.0) -> can.Message:
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None and msg.arbitration_id == 0xFF:
            return msg
    raise AssertionError("no reply on 0xFF")


def test_python_can_talks_to_the_virtual_motors(server: int) -> None:
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=server, channel="can0")
    try:
        ident, data = codec.encode(ReadRequest(2, 0x02, 2))  # target speed + acceleration
        bus.send(can.Message(arbitration_id=ident, data=data, is_extended_id=False))
        reply = recv_reply(bus)
        assert codec.decode_reply(0xFF, reply.data) == ReadReply(2, 0x02, (1000, 10000))
        # 5.3c: 0x301 writes motor 1's cache and answers its absolute position
        bus.send(can.Message(arbitration_id=0x301, data=bytes(4), is_extended_id=False))
        assert isinstance(codec.decode_reply(0xFF, recv_reply(bus).data), PositionReply)
    finally:
        bus.shutdown()


def test_connect_url_moves_one_motor_of_two(server: int) -> None:
    url = f"easycan+socketcand://127.0.0.1:{server}/can0"
    with connect(url, drive_id=2, timeout=0.2) as two, connect(url, drive_id=1) as one:
        assert two.protocol == "easycan" and two.family.name == "yzaim"
        start_one = one.position()
        two.move_by(two.revs(0.5), wait=True, timeout=10)
        assert two.status().idle
        assert one.position() == start_one
        assert abs(two.read_param("acceleration")) == 10000


def test_cli_status_set_move_and_scan(server: int) -> None:
    url = f"easycan+socketcand://127.0.0.1:{server}"

    def run(*args: str) -> subprocess.CompletedProcess[str]:  # roomy read deadline: load
        return subprocess.run([*SERVOBUS, "--timeout", "2", "--url", url, *args],
                              capture_output=True, text=True, timeout=60)

    out = run("--id", "1", "status", "--json")
    assert out.returncode == 0, out.stderr
    status = json.loads(out.stdout)
    assert "yzaim" in out.stdout and status
    assert run("--id", "1", "set", "max_current", "4000").returncode == 0
    got = run("--id", "1", "params", "--json")
    assert got.returncode == 0, got.stderr
    assert "4000" in got.stdout
    bad = run("--id", "1", "set", "target_speed", "3001")
    assert bad.returncode == 2 and "3001" in bad.stderr
    moved = run("--id", "1", "move", "--wait", str(Y.COUNTS_PER_REV // 4))
    assert moved.returncode == 0, moved.stderr
    scan = run("scan", "--per-id", "0.02")
    assert scan.returncode == 0, scan.stderr
    assert "1" in scan.stdout and "2" in scan.stdout


def test_state_file_keeps_saved_registers_across_restarts(tmp_path: Path) -> None:
    state = tmp_path / "yzaim.json"
    proc, port = start_server("--ids", "4", "--fast", "--state", str(state))
    url = f"easycan+socketcand://127.0.0.1:{port}"
    try:
        with connect(url, drive_id=4) as axis:
            axis.write_param("acceleration", 4321)
            axis.save_parameters()
            axis.write_param("target_speed", 222)  # not saved
    finally:
        proc.terminate()
        proc.wait(10)
    proc, port = start_server("--ids", "4", "--fast", "--state", str(state))
    try:
        with connect(f"easycan+socketcand://127.0.0.1:{port}", drive_id=4) as axis:
            assert axis.read_param("acceleration") == 4321
            assert axis.read_param("target_speed") == 1000
    finally:
        proc.terminate()
        proc.wait(10)
