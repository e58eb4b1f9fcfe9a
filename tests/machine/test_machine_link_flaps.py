"""Links that come back badly (issue 29, found by ``python -m benchmarks faults``): a peer that
accepts a connection and hangs up at once, a link that drops again soon after coming back,
a poll that reaches the reopened link before the power check, a power check that gets no
answer, and interrupted motion reported once (docs/machine.md, "Recovery")."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
from pathlib import Path

import pytest
from machine_rig import write_machine
from rig import free_port, wait_until_async

from servobus.axis import connect_async
from servobus.errors import DriveTimeout, MachineLinkError
from servobus.machine import machine as machine_module
from servobus.machine import open_machine_async
from servobus.machine.machine import RETRY_S, AsyncMachine
from servobus.protocols.dyn232.server import Dyn232Server
from servobus.sim.dmm.drive import VirtualDrive

SIMULATED_S = 60.0
ONE_AXIS = '[axes.a]\nurl = "{url}"\nid = 1\nunit = "rev"\n'


def servobus_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.levelno >= logging.INFO and r.name.startswith("servobus")]


class Clock:
    """The machine's reconnect clock, simulated: a sleep adds to ``now``; past ``limit`` it
    waits until :meth:`release` (a test looks at the machine meanwhile)."""

    def __init__(self, limit: float) -> None:
        self.now = 0.0
        self.limit = limit
        self.slept: list[float] = []
        self.parked = asyncio.Event()
        self._go = asyncio.Event()

    async def sleep(self, seconds: float) -> None:
        self.slept.append(seconds)
        if self.now + seconds > self.limit:
            self.parked.set()
            await self._go.wait()
            self._go.clear()
            self.parked.clear()
        self.now += seconds
        await asyncio.sleep(0)

    def release(self, more: float) -> None:
        self.limit = self.now + more
        self._go.set()


async def hang_up(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    writer.transport.abort()  # accept, then reset at once: a port forward with nothing behind


async def test_a_peer_that_accepts_and_hangs_up_is_one_drop_not_a_loop(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    port = free_port()
    line = Dyn232Server([VirtualDrive(1)], paced=False)
    await line.listen_tcp("127.0.0.1", port)
    clock = Clock(SIMULATED_S)
    url = f"dyn232+socket://127.0.0.1:{port}?timeout=2"
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS.format(url=url)),
                                       retry=True, sleep=clock.sleep)
    hanging: asyncio.Server | None = None
    try:
        axis = machine["a"]
        assert axis.online
        caplog.set_level(logging.DEBUG)
        await line.close()  # the drive's side goes; the same port now accepts and hangs up
        hanging = await asyncio.start_server(hang_up, "127.0.0.1", port, reuse_address=True)
        await asyncio.wait_for(clock.parked.wait(), 30)
        # every try connected and was reset: each one counted as failed, paced by the backoff
        assert machine.reconnect_tries == len(clock.slept)  # a sleep before each, bar the 1st
        assert not axis.online
        lines = servobus_lines(caplog)
        assert len(lines) == 1 and "is down" in lines[0], lines
        assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
        hanging.close()
        await hanging.wait_closed()
        line = Dyn232Server([VirtualDrive(1)], paced=False)
        await line.listen_tcp("127.0.0.1", port)
        clock.release(SIMULATED_S)
        await wait_until_async(lambda: axis.online and not axis.checking, timeout=30,
                               what="the axis online again")
        assert [x for x in servobus_lines(caplog) if "is online" in x] != []
        assert abs(await axis.position()) < 0.01
    finally:
        await machine.close()
        if hanging is not None:
            hanging.close()
        await line.close()


class Forward:
    """127.0.0.1:``port`` forwarded to ``upstream``; :meth:`cut` resets every connection."""

    def __init__(self, upstream: int) -> None:
        self.upstream = upstream
        self.open: set[asyncio.Transport] = set()
        self.server: asyncio.Server | None = None

    async def start(self) -> int:
        self.server = await asyncio.start_server(self._accepted, "127.0.0.1", 0)
        return int(self.server.sockets[0].getsockname()[1])

    async def _accepted(self, reader: asyncio.StreamReader,
                        writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream)
        self.open.update((writer.transport, up_writer.transport))
        await asyncio.gather(self._pump(reader, up_writer), self._pump(up_reader, writer))

    @staticmethod
    async def _pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with contextlib.suppress(OSError):
            while data := await reader.read(4096):
                writer.write(data)
        writer.transport.abort()

    def cut(self) -> None:
        for transport in self.open:
            transport.abort()
        self.open.clear()

    async def close(self) -> None:
        self.cut()
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()


def back(machine: AsyncMachine, tries: int) -> bool:
    axis = machine["a"]
    return machine.reconnect_tries == tries and axis.online and not axis.checking


async def test_a_link_that_drops_again_soon_after_coming_back_is_not_retried_at_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(machine_module, "STABLE_S", 3600.0)  # every drop here is "soon"
    line = Dyn232Server([VirtualDrive(1)], paced=False)
    _, upstream = await line.listen_tcp("127.0.0.1", 0)
    forward = Forward(upstream)
    port = await forward.start()
    clock = Clock(SIMULATED_S)
    url = f"dyn232+socket://127.0.0.1:{port}?timeout=2"
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS.format(url=url)),
                                       retry=True, sleep=clock.sleep)
    try:
        waits: list[list[float]] = []
        for tries in (1, 2, 3):
            await wait_until_async(lambda: len(forward.open) == 2, timeout=30,
                                   what="the machine's connection through the forward")
            forward.cut()
            await wait_until_async(functools.partial(back, machine, tries), timeout=30,
                                   what=f"reopen {tries}")
            waits.append(list(clock.slept))
        # the first drop (the link was up since start-up) is retried at once; each drop
        # soon after coming back waits RETRY_S, doubled
        assert waits == [[], [RETRY_S], [RETRY_S, 2 * RETRY_S]]
    finally:
        await machine.close()
        await forward.close()
        await line.close()


async def _drive_at(machine: AsyncMachine, target: float) -> None:
    await machine["a"].move_to(target, wait=True, timeout=30)
    assert abs(await machine["a"].position() - target) < 0.01


async def test_a_poll_on_the_reopened_link_does_not_hide_the_position_jump(
        tmp_path: Path) -> None:
    """The power check compares with the position before the drop, not with whatever a
    poll (the GUI's, the gateway's) read on the reopened link first."""
    url = "sim://dyn232?fast=1"
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS.format(url=url)))
    axis = machine["a"]
    old = axis.axis
    restarted = await connect_async(url, drive_id=1)  # a drive that powered up at 0
    try:
        await _drive_at(machine, 0.5)
        axis.went_offline(MachineLinkError("the link is down"))
        axis.axis = restarted  # the link is back (what Link.open does)
        assert abs(await axis.position()) < 0.01  # a poll first: the drive is at 0
        await axis.check_power()
        assert axis.power_lost and "moved from" in str(axis.power_lost_reason)
    finally:
        await machine.close()
        if old is not None:
            await old.close()


async def test_a_power_check_that_gets_no_answer_flags_the_position_unverified(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A check that times out (a loaded host) cannot tell a restart from none: flagged, and
    its reference is gone, so a later harmless drop is not flagged by it."""
    url = "sim://dyn232?fast=1"
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS.format(url=url)))
    axis = machine["a"]
    core = axis.axis
    assert core is not None
    try:
        await _drive_at(machine, 0.5)
        axis.went_offline(MachineLinkError("the link is down"))
        axis.axis = core

        async def no_answer() -> int:
            raise DriveTimeout("no reply from drive 1 (the test)")

        with monkeypatch.context() as patch:
            patch.setattr(core, "position", no_answer)
            with pytest.raises(DriveTimeout):
                await axis.check_power()
        assert axis.power_lost and "unverified" in str(axis.power_lost_reason)
        await axis.acknowledge()
        await _drive_at(machine, 1.0)  # the axis moves on, then its link drops, harmlessly
        axis.went_offline(MachineLinkError("the link is down"))
        axis.axis = core
        await axis.check_power()
        assert not axis.power_lost, axis.power_lost_reason
    finally:
        await machine.close()


async def test_an_interrupted_motion_is_logged_once_and_a_waited_move_interrupts_nothing(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    url = "sim://dyn232?fast=1"
    machine = await open_machine_async(write_machine(tmp_path, ONE_AXIS.format(url=url)))
    axis = machine["a"]
    core = axis.axis
    try:
        await _drive_at(machine, 0.25)  # wait=True: the move has ended
        axis.went_offline(MachineLinkError("the link is down"))
        assert axis.interrupted is None
        axis.axis = core
        await axis.move_by(50.0)  # still running when the link drops, twice
        caplog.set_level(logging.WARNING, logger="servobus.machine")
        axis.went_offline(MachineLinkError("the link is down"))
        axis.axis = core
        axis.went_offline(MachineLinkError("the link is down again"))
        assert axis.interrupted is not None
        assert [m for m in servobus_lines(caplog) if "interrupted" in m] == [
            f"axis a: motion interrupted by the link drop: {axis.interrupted}; "
            "it is not re-sent"]
        axis.axis = core
    finally:
        await machine.close()


async def test_acknowledge_waits_for_the_power_check(tmp_path: Path) -> None:
    """While a reopened link is being checked, the check may still flag a power loss the
    caller has not seen: acknowledge() is refused then (every front end asks the machine)."""
    path = write_machine(tmp_path, ONE_AXIS.format(url="sim://dyn232"))
    async with await open_machine_async(path) as machine:
        axis = machine["a"]
        axis.flag_power_lost("a test")
        axis.checking = True
        with pytest.raises(MachineLinkError, match="being checked"):
            await axis.acknowledge()
        assert axis.power_lost
        axis.checking = False
        await axis.acknowledge()
        assert not axis.power_lost
