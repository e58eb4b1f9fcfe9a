"""A page's jog cannot outlive its page (issue 27), across processes: a virtual DYN232M
line in its own process, ``servobus gui --machine`` in another, a WebSocket client here
holding a jog. The drive is read from outside with its own client; its travel after the
page stops renewing, or after the GUI is killed with SIGKILL, stays within the lease's
documented bound (``lead + v x STREAM_S``, servobus.machine.lease) and inside the soft
limit."""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from rig import wait_until
from subprocess_rig import read_line, stop_process
from websockets.sync.client import ClientConnection
from websockets.sync.client import connect as ws_connect

from servobus import connect
from servobus.axis.sync import Axis
from servobus.machine.lease import STREAM_S, lead

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
RPM = 300
LIMIT_REV = 200.0  # far enough: the jog never reaches it in these tests
TTL_S = 0.5  # the GUI's lease (servobus.gui.jog.LEASE_S)


@dataclass
class Rig:
    url: str  # the drive, for a client of our own
    gui: subprocess.Popen[str]
    base: str  # http://127.0.0.1:PORT/


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    sim = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "dyn232", "--fast",
                            "--ids", "1", "--listen", "tcp://127.0.0.1:0", "--duration", "80"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    gui: subprocess.Popen[str] | None = None
    try:
        line = read_line(sim, "listening on tcp://")
        url = "dyn232+socket://" + line.split("tcp://", 1)[1].split()[0]
        machine = tmp_path_factory.mktemp("lease") / "m.toml"
        machine.write_text(f'[axes.t]\nurl = "{url}"\nid = 1\nunit = "rev"\n'
                           f"limits = [-{LIMIT_REV}, {LIMIT_REV}]\n", encoding="utf-8")
        gui = subprocess.Popen([sys.executable, "-m", "servobus", "gui", "--machine",
                                str(machine), "--port", "0", "--no-browser"],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        first = read_line(gui, "servobus gui: http://")
        yield Rig(url, gui, first.split()[-1])
    finally:
        if gui is not None:
            stop_process(gui)
        stop_process(sim)


@pytest.fixture(scope="module")
def drive(rig: Rig) -> Iterator[Axis]:
    with connect(rig.url, drive_id=1) as axis:
        yield axis


def bound_counts(drive: Axis) -> float:
    """The documented bound on travel after the last renewal, plus what one read of the
    drive from here may lag (one more period at the asked speed)."""
    profile = drive.stream_profile()
    to_counts = drive.counts_per_rev / 60.0  # rpm -> counts/s
    v, a = RPM * to_counts, profile.accel_rpm_s * to_counts
    return lead(v, a) + v * STREAM_S + v * STREAM_S


def standstill(drive: Axis) -> int:
    """The drive's position once two reads 0.1 s apart agree and it reads 0 rpm."""
    last: list[int] = [drive.position()]

    def still() -> bool:
        time.sleep(0.1)  # two reads apart in time: the poll period of this wait
        now = drive.position()
        same = now == last[0] and drive.speed() == 0
        last[0] = now
        return same

    wait_until(still, timeout=20, what="the drive at standstill")
    return last[0]


@contextlib.contextmanager
def page(rig: Rig) -> Iterator[ClientConnection]:
    """A page's WebSocket, once the server said hello."""
    with ws_connect(rig.base.replace("http://", "ws://") + "ws", open_timeout=10) as ws:
        while json.loads(ws.recv(timeout=10))["type"] != "hello":
            pass
        yield ws


def hold_jog(ws: ClientConnection, drive: Axis, revs: float) -> None:
    """Renew a jog (as the page does while the button is held) until ``revs`` travelled."""
    start = drive.position()

    def travelled() -> bool:
        ws.send(json.dumps({"type": "jog", "axis": 1, "rpm": RPM}))
        return drive.position() - start > revs * drive.counts_per_rev

    wait_until(travelled, timeout=20, poll=0.1, what=f"a jog of {revs} rev")


def lease_ended(ws: ClientConnection) -> str:
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        doc: dict[str, Any] = json.loads(ws.recv(timeout=10))
        if doc["type"] == "status" and doc["ended"].get("1"):
            return str(doc["ended"]["1"])
    pytest.fail("the page was not told its jog ended")


def test_a_page_that_stops_renewing_loses_its_jog_within_the_ttl(rig: Rig,
                                                                   drive: Axis) -> None:
    with page(rig) as ws:
        hold_jog(ws, drive, 1.0)
        at_last_renewal = drive.position()
        t0 = time.monotonic()  # no more renewals; the socket stays open
        assert lease_ended(ws) == "expired"
        # a loaded machine may deliver the status late; idle it comes within the ttl
        assert time.monotonic() - t0 < TTL_S + 5.0
        rest = standstill(drive)
        # the lease ran on for its ttl after the last renewal, then stopped
        v = RPM * drive.counts_per_rev / 60.0
        window = drive.position_window()  # a servo at rest rings within it
        assert -window <= rest - at_last_renewal <= v * TTL_S + bound_counts(drive)


def test_sigkill_of_the_gui_during_a_held_jog_stops_the_drive_within_the_lead(
        rig: Rig, drive: Axis) -> None:
    with page(rig) as ws:
        hold_jog(ws, drive, 1.0)
        ws.send(json.dumps({"type": "jog", "axis": 1, "rpm": RPM}))  # the last renewal
        at_kill = drive.position()
        rig.gui.send_signal(signal.SIGKILL)  # nothing of the GUI runs after this
        rig.gui.wait(timeout=10)
        with contextlib.suppress(Exception):  # the peer is gone: the close may fail
            ws.close()
    rest = standstill(drive)
    travel = rest - at_kill
    # a servo at rest rings within its in-position window (a lease that lapsed on a loaded
    # machine before the kill leaves the motor standing): that much backwards is no travel
    window = drive.position_window()
    assert -window <= travel <= bound_counts(drive), (travel, bound_counts(drive))
    assert rest / drive.counts_per_rev < LIMIT_REV  # inside the soft limit
