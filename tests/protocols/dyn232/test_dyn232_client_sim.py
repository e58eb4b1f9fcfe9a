"""connect()/connect_async() end to end: sim:// (fast and paced), TCP, PTY, CLI server."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import time
from typing import Any

import pytest

from servobus.axis import AsyncAxis, Axis, connect, connect_async
from servobus.errors import ArgumentRangeError, DriveTimeout, ServobusError
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.server import Dyn232Server
from servobus.sim.dmm.drive import VirtualDrive
from servobus.transport.base import Direction
from servobus.transport.serial_stream import SerialStream
from servobus.transport.tcp_stream import TcpStream

pytestmark = pytest.mark.timeout(30)
FAST = "sim://dyn2?fast=1"
#: A servoed motor settles within OnRange of its target (default 10/16384 rev = 40 counts).
TOLERANCE = round(U.onrange_to_counts(P.spec("on_range").default))


def near(actual: int, target: int) -> bool:
    return abs(actual - target) <= TOLERANCE


def test_default_connect_is_the_embedded_drive() -> None:
    with connect() as axis:
        assert isinstance(axis, Axis)
        assert (axis.protocol, axis.drive_id) == ("dyn232", 0)
        assert axis.read_id() == 0
        assert axis.read_params() == {n: P.spec(n).default for n in P.DYN_PARAMS}


def test_sync_facade_moves_and_siblings_share_the_line() -> None:
    with connect("sim://dyn2?ids=0,1,2&fast=1", drive_id=1) as axis:
        axis.move_by(2000, wait=True, timeout=10)  # counts
        assert near(axis.position(), 2000)
        two = axis.sibling(2)
        assert two.read_id() == 2
        assert near(two.position(), 0)
        two.close()  # a sibling does not close the line
        assert axis.ping()
        assert not axis.sibling(5).ping(timeout=0.02)


#: The same call sequence for the sync facade and the async core; index 4 is the position.
CALLS: list[tuple[str, tuple[Any, ...]]] = [
    ("write_param", ("max_accel", 60)), ("read_params", ()), ("move_to", (1200,)),
    ("wait_idle", (10.0, 0.005)), ("position", ()), ("status", ()), ("config", ()),
    ("read_id", ()), ("ping", ()),
]


def test_sync_facade_and_async_core_give_the_same_results() -> None:
    calls = CALLS
    with connect(FAST) as axis:
        # config() is a DYN232M extra: axis.extra on the sync facade
        sync_results = [getattr(axis.extra if name == "config" else axis, name)(*args)
                        for name, args in calls]

    async def run_async() -> list[object]:
        async with await connect_async(FAST) as core:
            return [await getattr(core, name)(*args) for name, args in calls]

    async_results = asyncio.run(run_async())
    positions = sync_results.pop(4), async_results.pop(4)
    assert sync_results == async_results  # everything but the servoed position: exact
    assert all(isinstance(p, int) and near(p, 1200) for p in positions)


async def test_paced_round_trip_takes_the_wire_time() -> None:
    core = await connect_async("sim://dyn2")  # paced at 38400 8N1
    try:
        await core.status()  # warm up
        t0 = time.perf_counter()
        await core.status()  # 4 bytes out + 4 bytes back = 8 x 260 us
        assert time.perf_counter() - t0 >= 0.002
    finally:
        await core.close()


async def test_absent_id_on_sim_times_out() -> None:
    core = await connect_async(FAST + "&ids=0", drive_id=7, retries=1, timeout=0.02)
    try:
        assert not await core.ping(timeout=0.02)
        with pytest.raises(DriveTimeout):
            await core.read_param("main_gain")
    finally:
        await core.close()


def test_connect_rejects_bad_arguments_before_opening() -> None:
    with pytest.raises(ArgumentRangeError):
        connect(FAST, drive_id=64)
    with pytest.raises(ArgumentRangeError):
        connect(FAST, nonsense=1)
    with pytest.raises(ArgumentRangeError):
        connect("socket://127.0.0.1:1", can="virtual:x")
    with pytest.raises(ServobusError):
        connect("socket://127.0.0.1:1")  # nothing listens on port 1


# ---------------------------------------------------------------------- TCP and PTY
async def _exercise(core: AsyncAxis, drives: list[VirtualDrive]) -> None:
    assert await core.read_id() == core.drive_id
    await core.write_params({"main_gain": 90, "gear_num": 8192})
    assert (await core.read_params())["main_gain"] == 90
    await core.move_to(-2000, wait=True, timeout=10)  # counts, whatever GEAR_NUM is
    assert near(await core.position(), -2000)
    mine = next(d for d in drives if d.drive_id == core.drive_id)
    assert mine.get_param("gear_num") == 8192


@pytest.mark.parametrize("transport", ["tcp", "pyserial"])
async def test_over_tcp_server(transport: str) -> None:
    server = Dyn232Server([VirtualDrive(3), VirtualDrive(4)], paced=False)
    host, port = await server.listen_tcp("127.0.0.1", 0)
    try:
        core = await connect_async(f"socket://{host}:{port}", drive_id=4, transport=transport)
        assert isinstance(core, Dyn232Axis)
        assert isinstance(core.client.stream,
                          TcpStream if transport == "tcp" else SerialStream)
        try:
            await _exercise(core, server.drives)
        finally:
            await core.close()
    finally:
        await server.close()


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a POSIX pty")
async def test_over_pty() -> None:
    server = Dyn232Server([VirtualDrive(0)], paced=False)
    path = server.open_pty()
    try:
        core = await connect_async(path, query_interval_s=0.0, timeout=2.0)  # roomy: load
        try:
            await _exercise(core, server.drives)
        finally:
            await core.close()
    finally:
        await server.close()


def test_against_cli_server_subprocess() -> None:
    """`servobus sim dyn232 --listen tcp://127.0.0.1:0 --fast --duration N` in its own process."""
    proc = subprocess.Popen(
        [sys.executable, "-c", "from servobus.cli.main import main; main()",
         "sim", "dyn232", "--listen", "tcp://127.0.0.1:0", "--ids", "1,2", "--fast",
         "--duration", "20"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        if not line:
            pytest.fail(f"server did not start: {proc.stderr.read() if proc.stderr else ''}")
        assert line.startswith("listening on tcp://"), line
        url = "socket://" + line.split("tcp://", 1)[1].strip()
        with connect(url, drive_id=2) as axis:
            trace: list[tuple[Direction, object]] = []
            axis.add_trace(lambda d, item, t: trace.append((d, item)))
            assert axis.read_id() == 2
            axis.move_by(256, wait=True, timeout=10)
            assert near(axis.position(), 256)
            assert axis.sibling(1).read_id() == 1
            assert [d for d, _ in trace[:2]] == [Direction.TX, Direction.RX]
    finally:
        proc.terminate()
        proc.wait(10)
