"""The sync facade runs EtherNet/IP and DYN232M-over-TCP calls on the caller's thread (issue
22), with the core's rules intact: the deadline holds with no loop thread, a late reply is
dropped, pyserial's socket handler works too, and the results are the loop thread's."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest

from servobus.axis import connect
from servobus.axis.inline import ENV, InlineRunner
from servobus.axis.sync import Axis, LoopThread
from servobus.errors import DriveTimeout
from servobus.families.dmm.registers import StatusBits
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.enip.server import EnipFleet, start_fleet

pytestmark = pytest.mark.timeout(60)
WAIT_S = 10.0  # generous: only a hang reaches it
REQUEST = c.encode(0, DmmFunction.READ_DRIVE_STATUS, 0)


def _inline(axis: Axis) -> bool:
    runner = axis._runner
    return isinstance(runner, InlineRunner) and runner.inline


# ---------------------------------------------------------------------- EtherNet/IP
@pytest.fixture
def fleet() -> Iterator[EnipFleet]:
    server_loop = LoopThread("test-adapters")
    running = server_loop.run(start_fleet("127.0.0.1", 0, 0, reset_downtime_s=0.3))
    try:
        yield running
    finally:
        server_loop.run(running.stop())
        server_loop.stop()


def _reads(url: str) -> tuple[int, int, bool]:
    with connect(url, timeout=1.0) as axis:
        assert axis.read_param("main_gain") >= 0
        axis.write_param("main_gain", 45)
        return axis.position(), axis.read_param("main_gain"), _inline(axis)


def test_enip_runs_inline_and_reads_what_the_loop_thread_reads(
        fleet: EnipFleet, monkeypatch: pytest.MonkeyPatch) -> None:
    server = fleet.servers[0]
    url = f"enip://{server.host}:{server.tcp_port}"
    with connect(url) as axis:
        seen: set[int] = set()
        axis.add_trace(lambda direction, item, t: seen.add(threading.get_ident()))
        axis.position()
        assert _inline(axis) and seen == {threading.get_ident()}  # the caller's thread
    inline_reads = _reads(url)
    monkeypatch.setenv(ENV, "thread")
    thread_reads = _reads(url)
    assert inline_reads[:2] == thread_reads[:2] == (0, 45)
    assert inline_reads[2] and not thread_reads[2]


# ---------------------------------------------------------------------- DYN232M over TCP
class _Bridge:
    """A scripted serial-to-Ethernet bridge: each status request waits for a go (an Event)
    before its reply, whose status byte the test names."""

    def __init__(self, replies: list[tuple[threading.Event | None, int]]) -> None:
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._replies = replies
        self.sent: list[threading.Event] = [threading.Event() for _ in replies]
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        self._listener.settimeout(WAIT_S)
        conn, _ = self._listener.accept()
        with conn:
            conn.settimeout(WAIT_S)
            for (go, status), sent in zip(self._replies, self.sent, strict=True):
                got = b""
                while len(got) < len(REQUEST):
                    got += conn.recv(len(REQUEST) - len(got))
                assert got == REQUEST
                if go is not None:
                    go.wait(WAIT_S)
                conn.sendall(c.encode_reply(0, c.DriveFunction.IS_STATUS, status))
                sent.set()
            while conn.recv(64):  # until the client closes
                pass

    def close(self) -> None:
        self._thread.join(WAIT_S)
        self._listener.close()


def test_dyn232_deadline_and_late_reply_inline() -> None:
    late = threading.Event()
    bridge = _Bridge([(late, StatusBits.SERVO_FREE), (None, 0)])
    try:
        with connect(f"socket://127.0.0.1:{bridge.port}", timeout=0.05, retries=0,
                     late_reply_s=WAIT_S) as axis:
            assert _inline(axis)
            with pytest.raises(DriveTimeout):  # the deadline fires with no loop thread
                axis.extra.drive_status()
            late.set()
            assert bridge.sent[0].wait(WAIT_S)  # the late reply is in the socket now
            assert not axis.extra.drive_status().servo_free  # the second reply, not the late
            assert axis.core.client.transactions.stats.late_replies == 1
    finally:
        bridge.close()


def test_dyn232_pyserial_socket_inline() -> None:
    bridge = _Bridge([(None, StatusBits.SERVO_FREE), (None, 0)])
    try:
        with connect(f"socket://127.0.0.1:{bridge.port}?transport=pyserial",
                     timeout=1.0) as axis:
            assert axis.extra.drive_status().servo_free
            assert not axis.extra.drive_status().servo_free
            assert _inline(axis)
    finally:
        bridge.close()
