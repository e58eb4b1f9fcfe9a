"""Opening a YZ-AIM motor over Modbus RTU from a URL: the URL forms, options checked before
anything is opened, and both reception paths against ``servobus sim modbus`` (asyncio TCP
pushes; pyserial's socket:// handler is read by the transaction manager's pull)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import pytest

from servobus.axis import connect_async, registry
from servobus.axis.url import parse_url
from servobus.errors import ArgumentRangeError, ServobusError
from servobus.protocols.modbus.axis import ModbusAxis
from servobus.protocols.modbus.opener import port_url
from servobus.transport.serial_stream import SerialStream
from servobus.transport.tcp_stream import TcpStream

pytestmark = pytest.mark.timeout(60)
SAFETY_NET_S = "600"  # --duration: the fixture stops it; a loaded module takes minutes


@pytest.mark.parametrize(("url", "port"), [
    ("modbus:///dev/ttyUSB0?baud=19200", "/dev/ttyUSB0"),
    ("modbus:COM3", "COM3"),
    ("modbus+socket://127.0.0.1:4001", "socket://127.0.0.1:4001"),
    ("modbus+rfc2217://host:2217?timeout=0.5", "rfc2217://host:2217"),
])
def test_url_forms(url: str, port: str) -> None:
    parsed = parse_url(url)
    assert port_url(parsed) == port
    assert registry.protocol_of(parsed) == "modbus"


@pytest.mark.parametrize("url", [
    "modbus:///dev/ttyUSB0?parity=E", "modbus:///dev/ttyUSB0?baud=0",
    "modbus:///dev/ttyUSB0?retries=-1", "modbus:///dev/ttyUSB0?transport=udp",
    "modbus:///dev/ttyUSB0?frame_gap_s=nan", "modbus:", "modbus+socket://h:1?timeout=0",
])
async def test_bad_urls_are_refused_before_opening(url: str) -> None:
    with pytest.raises(ArgumentRangeError):
        await connect_async(url)


@pytest.mark.parametrize("drive_id", [0, 255, -1])
async def test_bad_ids_are_refused(drive_id: int) -> None:
    with pytest.raises(ArgumentRangeError):
        await connect_async("modbus:///dev/does-not-exist", drive_id=drive_id)


async def test_a_missing_port_is_a_servobus_error() -> None:
    with pytest.raises(ServobusError, match="cannot open"):
        await connect_async("modbus:///dev/servobus-no-such-port")


@pytest.fixture(scope="module")
def line() -> Iterator[str]:
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "modbus", "--ids", "1,5",
                             "--listen", "tcp://127.0.0.1:0", "--duration", SAFETY_NET_S],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline().strip()
        assert first.startswith("listening on tcp://"), first
        yield first.split("tcp://", 1)[1]
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.mark.parametrize(("transport", "stream_type"), [("auto", TcpStream),
                                                        ("pyserial", SerialStream)])
async def test_both_reception_paths_against_the_paced_line(line: str, transport: str,
                                                           stream_type: type) -> None:
    axis = await connect_async(f"modbus+socket://{line}?transport={transport}", drive_id=5)
    assert isinstance(axis, ModbusAxis)
    try:
        assert isinstance(axis.client.stream, stream_type)
        assert await axis.read_id() == 5
        await axis.move_by(4096, wait=True, timeout=10)
        assert abs(await axis.position() - 4096) <= 10
        ghost = await axis.sibling(9)
        assert await ghost.ping(0.1) is False
        assert await axis.ping(0.5)
        await axis.move_by(-4096, wait=True, timeout=10)
    finally:
        await axis.close()
