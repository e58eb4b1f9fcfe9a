"""The virtual DYN2 line served over TCP, a PTY and a tap (subprocess CLI and in-process)."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import serial
from subprocess_rig import read_line, stop_process

from servobus.errors import ArgumentRangeError
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.pacing import BYTE_TIME_S
from servobus.protocols.dyn232.server import Dyn232Server
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.line_server import parse_listen_url

pytestmark = pytest.mark.slow  # real processes or seconds of wall-clock motion

H, D, GR = c.HostFunction, c.DriveFunction, c.GeneralReadSelector
CLI = [sys.executable, "-c", "from servobus.cli.main import main; main()"]


class SimProcess:
    """``servobus sim dyn232 ...`` in a subprocess; always bounded by --duration."""

    def __init__(self, *args: str, duration: float = 20.0) -> None:
        self.proc = subprocess.Popen(
            [*CLI, "sim", "dyn232", *args, "--duration", str(duration)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )

    def line(self, timeout: float = 15.0) -> str:
        return read_line(self.proc, timeout=timeout)

    def tcp_port(self) -> int:
        text = self.line()
        assert text.startswith("listening on tcp://127.0.0.1:"), text
        return int(text.rsplit(":", 1)[1])

    def stop(self) -> int:
        stop_process(self.proc, timeout=10)
        return self.proc.returncode


@contextlib.contextmanager
def sim(*args: str, duration: float = 20.0) -> Iterator[SimProcess]:
    p = SimProcess(*args, duration=duration)
    try:
        yield p
    finally:
        p.stop()


REPLY_S = 10.0  # a reply ends the read at once
SILENCE_S = 0.3  # how long nothing must come


def transact(port: serial.SerialBase, request: bytes, timeout: float = REPLY_S,
             ) -> list[c.Packet]:
    """Write one packet and collect its reply: bytes one at a time (a read of more waits for
    all of them or the timeout) until a whole packet came, or none within ``timeout``."""
    port.timeout = timeout
    port.reset_input_buffer()
    port.write(request)
    got = b""
    while True:
        chunk = port.read(1)
        if not chunk:
            break
        got += chunk
        events = c.Framer().feed(got)
        if events and len(got) >= 4:
            break
    events = c.Framer().feed(got)
    assert all(isinstance(e, c.Packet) for e in events), events
    return [e for e in events if isinstance(e, c.Packet)]


def round_trip_s(sock: socket.socket, request: bytes, reply_len: int) -> float:
    t = time.perf_counter()
    sock.sendall(request)
    got = b""
    while len(got) < reply_len:
        chunk = sock.recv(64)
        assert chunk, "connection closed"
        got += chunk
    elapsed = time.perf_counter() - t
    assert len(got) == reply_len
    return elapsed


# ---------------------------------------------------------------- subprocess, TCP
def test_tcp_line_with_pyserial_socket_url() -> None:
    with sim("--ids", "1,2,3", "--fast", "--listen", "tcp://127.0.0.1:0") as p:
        port = p.tcp_port()
        # a reply ends a read at once: its deadline is generous (a loaded machine answered
        # later than 0.3 s); a silence is a window (it waits that long either way)
        ser = serial.serial_for_url(f"socket://127.0.0.1:{port}")
        try:
            for drive_id in (1, 2, 3):
                (reply,) = transact(ser, c.encode(drive_id, DF.READ_DRIVE_ID))
                assert (reply.drive_id, reply.function, reply.reply_value()) == (
                    drive_id, D.IS_DRIVE_ID, drive_id)
            assert transact(ser, c.encode(5, DF.READ_DRIVE_ID), SILENCE_S) == []  # absent
            ser.timeout = SILENCE_S
            ser.write(c.encode(2, DF.GO_RELATIVE_POS, 100))
            assert ser.read(16) == b""  # motion commands get no reply
            (pos,) = transact(ser, c.encode(2, DF.GENERAL_READ, GR.POSITION))
            assert pos.function == D.IS_ABS_POS32
        finally:
            ser.close()
        assert p.stop() == 0  # SIGTERM stops it cleanly


def test_paced_round_trip_takes_wire_time_and_fast_is_much_faster() -> None:
    """Paced: no round trip is ever shorter than the wire allows. Fast: some round trip is
    (a rate that is possible, not one this machine must keep: how much faster is a benchmark
    figure); the fast run stops at the first such round trip, so idle it is one or two."""
    request = c.encode(0, DF.READ_DRIVE_STATUS)
    wire_s = 8 * BYTE_TIME_S  # 4 + 4 bytes at 38400 8N1 = 2.08 ms
    with sim() as p, socket.create_connection(("127.0.0.1", p.tcp_port()), timeout=5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        paced = [round_trip_s(sock, request, 4) for _ in range(15)]
    assert min(paced) >= wire_s, paced
    with sim("--fast") as p, \
            socket.create_connection(("127.0.0.1", p.tcp_port()), timeout=5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        fast: list[float] = []
        while not fast or min(fast) >= wire_s / 2:
            assert len(fast) < 500, sorted(fast)[:5]
            fast.append(round_trip_s(sock, request, 4))


def test_pty_line_with_pyserial() -> None:
    with sim("--pty", "--ids", "7", "--fast") as p:
        text = p.line()
        assert text.startswith("pty /dev/"), text
        ser = serial.Serial(text.split(" ", 1)[1], 38400)
        try:
            (reply,) = transact(ser, c.encode(7, H.READ_GEAR_NUMBER))
            assert (reply.drive_id, reply.function, reply.reply_value()) == (
                7, D.IS_GEAR_NUMBER, 4096)
            assert transact(ser, c.encode(0, H.READ_GEAR_NUMBER), SILENCE_S) == []
        finally:
            ser.close()


def test_state_file_keeps_id_and_parameters_across_restart(tmp_path: Path) -> None:
    state = str(tmp_path / "eeprom.json")
    with sim("--ids", "1", "--fast", "--state", state) as p:
        with socket.create_connection(("127.0.0.1", p.tcp_port()), timeout=5) as sock:
            sock.sendall(c.encode(1, H.SET_MAIN_GAIN, 55) + c.encode(1, DF.ASSIGN_DRIVE_ID, 9))
            round_trip_s(sock, c.encode(9, DF.READ_DRIVE_ID), 4)  # both writes executed
        assert p.stop() == 0
    with sim("--ids", "1", "--fast", "--state", state) as p:
        ser = serial.serial_for_url(f"socket://127.0.0.1:{p.tcp_port()}")
        try:
            assert transact(ser, c.encode(1, DF.READ_DRIVE_ID), SILENCE_S) == []
            (gain,) = transact(ser, c.encode(9, H.READ_MAIN_GAIN))
            assert (gain.drive_id, gain.reply_value()) == (9, 55)
        finally:
            ser.close()


def test_duration_stops_the_server_by_itself() -> None:
    p = SimProcess("--fast", duration=0.3)
    try:
        p.tcp_port()
        assert p.proc.wait(timeout=15) == 0
    finally:
        p.stop()


def test_bad_ids_are_refused() -> None:
    out = subprocess.run([*CLI, "sim", "dyn232", "--ids", "1,99", "--duration", "0"],
                         capture_output=True, text=True, timeout=30)
    assert out.returncode != 0 and "99" in out.stderr


# ---------------------------------------------------------------- in-process server
def test_listen_url_defaults_to_localhost() -> None:
    assert parse_listen_url("tcp://:4001") == ("127.0.0.1", 4001)
    assert parse_listen_url(":0") == ("127.0.0.1", 0)
    assert parse_listen_url("4001") == ("127.0.0.1", 4001)
    assert parse_listen_url("tcp://0.0.0.0:4001") == ("0.0.0.0", 4001)  # only when asked
    for bad in ("udp://127.0.0.1:1", "tcp://127.0.0.1", "tcp://127.0.0.1:99999"):
        with pytest.raises(ArgumentRangeError):
            parse_listen_url(bad)


async def _read_packets(reader: asyncio.StreamReader, n: int) -> list[c.Packet]:
    framer, out = c.Framer(), list[c.Packet]()
    while len(out) < n:
        chunk = await asyncio.wait_for(reader.read(64), 2.0)
        assert chunk
        out += [e for e in framer.feed(chunk) if isinstance(e, c.Packet)]
    return out


async def _until(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    """Yield to the loop until ``condition`` holds (the server runs on this same loop)."""
    async with asyncio.timeout(timeout):
        while not condition():
            await asyncio.sleep(0.001)  # the polling helper's own short sleep


def test_several_clients_each_get_their_own_replies_and_tap_sees_all() -> None:
    async def run() -> None:
        server = Dyn232Server([VirtualDrive(1), VirtualDrive(2)], paced=False)
        host, port = await server.listen_tcp("127.0.0.1", 0)
        _, tap_port = await server.listen_tap("127.0.0.1", 0)
        tap_r, tap_w = await asyncio.open_connection(host, tap_port)
        r1, w1 = await asyncio.open_connection(host, port)
        r2, w2 = await asyncio.open_connection(host, port)
        await _until(lambda: server.tap_count == 1)  # the tap is accepted: it sees everything
        req1, req2 = c.encode(1, DF.READ_DRIVE_ID), c.encode(2, DF.READ_DRIVE_ID)
        w1.write(req1[:2])  # half a packet from client 1 ...
        w2.write(req2)  # ... does not corrupt client 2's packet
        await w1.drain()
        await w2.drain()
        assert [p.drive_id for p in await _read_packets(r2, 1)] == [2]
        w1.write(req1[2:])
        assert [p.drive_id for p in await _read_packets(r1, 1)] == [1]
        with pytest.raises(TimeoutError):  # client 2 never sees client 1's reply
            await asyncio.wait_for(r2.read(64), 0.1)
        tapped = b""
        expected = req2 + c.encode(2, D.IS_DRIVE_ID, 2, unsigned=True)
        while len(tapped) < 2 * len(expected):
            tapped += await asyncio.wait_for(tap_r.read(64), 2.0)
        assert tapped.startswith(expected)
        assert set(c.Framer().feed(tapped)) == {c.decode(req1), c.decode(req2),
                                                 c.Packet(1, D.IS_DRIVE_ID, b"\x01"),
                                                 c.Packet(2, D.IS_DRIVE_ID, b"\x02")}
        for w in (w1, w2, tap_w):
            w.close()
        await server.close()

    asyncio.run(run())


def test_paced_tap_orders_bytes_as_on_the_wire() -> None:
    """Two pipelined reads: the tap shows request, request, reply, reply in wire order."""

    async def run() -> None:
        server = Dyn232Server([VirtualDrive(0)], paced=True)
        host, port = await server.listen_tcp("127.0.0.1", 0)
        _, tap_port = await server.listen_tap("127.0.0.1", 0)
        tap_r, tap_w = await asyncio.open_connection(host, tap_port)
        r, w = await asyncio.open_connection(host, port)
        await _until(lambda: server.tap_count == 1)
        req = c.encode(0, DF.READ_DRIVE_ID) + c.encode(0, DF.READ_DRIVE_CONFIG)
        t = time.monotonic()
        w.write(req)
        replies = await _read_packets(r, 2)
        elapsed = time.monotonic() - t
        assert [p.function for p in replies] == [D.IS_DRIVE_ID, D.IS_CONFIG]
        assert elapsed >= 12 * BYTE_TIME_S  # 8 request bytes, then the 2nd reply's 4 bytes
        tapped = b""
        while len(tapped) < 16:
            tapped += await asyncio.wait_for(tap_r.read(64), 2.0)
        reply1 = c.encode(0, D.IS_DRIVE_ID, 0, unsigned=True)
        reply2 = c.encode(0, D.IS_CONFIG, 0, unsigned=True)
        # request 2 and reply 1 both end 8 byte times after the start (full duplex): either
        # may come first; reply 2 ends 4 byte times later.
        assert tapped[:4] == req[:4] and tapped[12:] == reply2
        assert tapped[4:12] in (req[4:] + reply1, reply1 + req[4:])
        for wr in (w, tap_w):
            wr.close()
        await server.close()

    asyncio.run(run())
