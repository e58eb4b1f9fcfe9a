"""Links that come back by themselves (issue 29): the reconnect backoff on a simulated clock,
a link with nothing listening in every URL form (typed, quiet, no busy loop), a port that
accepts and never answers, and the virtual drive killed and restarted under a running
machine for every protocol (docs/machine.md, "Recovery")."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import machine_rig
import pytest
from drive_process_rig import SIMS, sim_url, start_sim
from drive_process_rig import procs as procs  # the fixture, for this module
from machine_rig import write_machine
from rig import free_port, wait_until_async

from servobus import connect
from servobus.axis import registry
from servobus.errors import (
    ClosedError,
    ConnectionLost,
    DriveTimeout,
    MachineLinkError,
    PowerLostError,
    ServobusError,
)
from servobus.machine import open_machine, open_machine_async
from servobus.machine.machine import RETRY_MAX_S, RETRY_S, AsyncMachine, backoff
from servobus.transport import can_bus

SIMULATED_S = 60.0


def allowed_tries(seconds: float) -> int:
    """Tries the documented backoff allows in ``seconds`` when every try fails at once: one
    at 0, then after 0.1, 0.2, 0.4 ... s, at most 2 s apart (computed here from the rule,
    not from the code's generator)."""
    t, delay, tries = 0.0, RETRY_S, 1
    while t + delay <= seconds:
        t += delay
        tries += 1
        delay = min(delay * 2, RETRY_MAX_S)
    return tries


def machine_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    """What the machine logged at INFO and above (a loaded run may add asyncio's own)."""
    return [r.getMessage() for r in caplog.records
            if r.levelno >= logging.INFO and r.name.startswith("servobus")]


def test_the_backoff_is_0_01_doubling_to_2() -> None:
    delays = backoff()
    assert [next(delays) for _ in range(8)] == [0.0, 0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0]
    assert allowed_tries(SIMULATED_S) == 34  # 0, 0.1, 0.3, 0.7, 1.5, 3.1, then 5.1 ... 59.1


async def test_60_simulated_seconds_give_the_tries_the_backoff_allows(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    registry.register("flaky", "machine_rig:flaky_open")
    machine_rig.FLAKY.update(down=True, attempts=0)
    clock = [0.0]
    parked = asyncio.Event()
    never = asyncio.Event()

    async def sleep(seconds: float) -> None:  # the reconnect clock, simulated
        if clock[0] + seconds > SIMULATED_S:
            parked.set()
            await never.wait()  # the machine's close cancels it
        clock[0] += seconds
        await asyncio.sleep(0)  # let the loop turn, as a real sleep would

    text = machine_rig.MIXED + '\n[axes.z]\nurl = "flaky://line"\nid = 3\nunit = "rev"\n'
    caplog.set_level(logging.DEBUG, logger="servobus.machine")
    machine = await open_machine_async(write_machine(tmp_path, text), retry=True, sleep=sleep)
    try:
        await asyncio.wait_for(parked.wait(), 30)
        assert machine_rig.FLAKY["attempts"] == allowed_tries(SIMULATED_S)
        assert machine.reconnect_tries == allowed_tries(SIMULATED_S) - 1  # + the start-up open
        assert not machine["z"].online
        lines = machine_lines(caplog)
        assert len(lines) == 1 and "cannot open flaky://line" in lines[0]
    finally:
        await machine.close()


#: Every URL form of every protocol with nothing behind it: a TCP port nobody listens on
#: ({port}), a serial port that does not exist ({missing}), a CAN interface that does not
#: exist (or an OS without CAN sockets).
NOTHING_LISTENING = {
    "dyn232 over TCP": "dyn232+socket://127.0.0.1:{port}",
    "bare pyserial URL": "socket://127.0.0.1:{port}",
    "dyn232 serial port": "dyn232://{missing}",
    "dyncan over socketcand": "dyncan+socketcand://127.0.0.1:{port}",
    "dyncan on socketcan": "dyncan+socketcan://nocan29",
    "easycan over socketcand": "easycan+socketcand://127.0.0.1:{port}",
    "easycan on socketcan": "easycan+socketcan://nocan29",
    "enip": "enip://127.0.0.1:{port}",
    "modbus over TCP": "modbus+socket://127.0.0.1:{port}",
    "modbus serial port": "modbus://{missing}",
}


def dead_url(form: str, tmp_path: Path) -> str:
    return NOTHING_LISTENING[form].format(port=free_port(), missing=tmp_path / "ttyNONE")


@pytest.mark.parametrize("form", sorted(NOTHING_LISTENING))
def test_nothing_listening_is_one_typed_error_and_quiet(
        form: str, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    url = dead_url(form, tmp_path)
    with pytest.raises(ServobusError) as info:
        connect(url)
    assert isinstance(info.value, ConnectionLost | DriveTimeout), repr(info.value)
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A port that accepts connections and never says a word."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        yield int(server.getsockname()[1])


@pytest.mark.parametrize("scheme", ["dyncan", "easycan"])
def test_a_socketcand_port_that_never_greets_is_a_typed_error(
        scheme: str, silent_port: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """python-can waits for the daemon's ``< hi >`` with no timeout: connect() hung for ever."""
    monkeypatch.setattr(can_bus, "SOCKETCAND_CONNECT_S", 0.3)
    with pytest.raises(ConnectionLost, match=r"no greeting within 0\.3 s"):
        connect(f"{scheme}+socketcand://127.0.0.1:{silent_port}")


def test_an_enip_port_that_never_answers_is_a_timeout(silent_port: int) -> None:
    with pytest.raises(DriveTimeout, match="REGISTER_SESSION"):
        connect(f"enip://127.0.0.1:{silent_port}?connect_timeout=0.3")


@pytest.mark.parametrize("form", sorted(NOTHING_LISTENING))
async def test_a_machine_waiting_for_a_dead_link_logs_once(
        form: str, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    url = dead_url(form, tmp_path)
    path = write_machine(tmp_path, f'[axes.c]\nurl = "{url}"\nid = 1\nunit = "deg"\n')
    with pytest.raises(MachineLinkError, match="axis c: cannot open"):
        await open_machine_async(path)
    caplog.clear()
    caplog.set_level(logging.DEBUG)
    clock, parked, never = [0.0], asyncio.Event(), asyncio.Event()

    async def sleep(seconds: float) -> None:  # the reconnect clock, simulated
        if clock[0] + seconds > SIMULATED_S:
            parked.set()
            await never.wait()  # the machine's close cancels it
        clock[0] += seconds
        await asyncio.sleep(0)

    machine = await open_machine_async(path, retry=True, sleep=sleep)
    try:
        await asyncio.wait_for(parked.wait(), 30)
        assert machine.reconnect_tries == allowed_tries(SIMULATED_S) - 1  # + the first open
        with pytest.raises(MachineLinkError, match="axis c is offline"):
            await machine["c"].position()
        lines = machine_lines(caplog)
        assert len(lines) == 1 and "cannot open" in lines[0], lines
    finally:
        await machine.close()


async def test_after_close_every_call_is_a_servobus_error(tmp_path: Path) -> None:
    machine = await open_machine_async(write_machine(tmp_path))
    await machine.close()
    with pytest.raises(ClosedError):
        await machine.stop_all()
    with pytest.raises(ClosedError):
        await machine["x"].position()
    sync = open_machine(write_machine(tmp_path, name="n.toml"))
    sync.close()
    for call in (sync.stop_all, sync["x"].position):
        with pytest.raises(ServobusError):
            call()


async def test_a_status_read_in_flight_during_a_move_does_not_hide_the_motion(
        tmp_path: Path) -> None:
    """A front end polls while it moves the axis: a status read sent before the move and
    answered "not moving" must not make a drop right after the move look like no motion
    ran (the gateway's restart test lost the power-loss flag that way)."""
    # paced like the wire: the status reply comes after the move has been handed over
    path = write_machine(tmp_path, '[axes.a]\nurl = "sim://dyn232"\nid = 1\nunit = "rev"\n')
    machine = await open_machine_async(path)
    try:
        axis = machine["a"]
        core = axis.core()
        read = asyncio.create_task(axis.status())
        await asyncio.sleep(0)  # one loop turn: the status request goes out first
        await axis.move_to(20.0)  # no read first: the move follows the status request
        assert not (await read).moving  # answered before the drive took the move
        axis.went_offline(MachineLinkError("the link dropped"))  # as the machine does
        assert axis.interrupted == "a commanded motion may not have finished"
        await core.stop()
        await core.close()
    finally:
        await machine.close()


# ------------------------------------------------------------ virtual drives in processes
async def offline(machine: AsyncMachine, name: str) -> bool:
    """Reads (as the GUI and the gateway poll) until the axis is offline."""
    axis = machine[name]
    with contextlib.suppress(ServobusError):
        await axis.position()
    return not axis.online


@pytest.mark.slow
@pytest.mark.parametrize("protocol", sorted(SIMS))
async def test_a_restarted_drive_comes_back_online(
        protocol: str, tmp_path: Path, procs: list[subprocess.Popen[str]]) -> None:
    port = free_port()
    procs.append(start_sim(protocol, port))
    url = sim_url(protocol, port)
    path = write_machine(tmp_path, f'[axes.a]\nurl = "{url}"\nid = 1\nunit = "rev"\n')
    machine = await open_machine_async(path, retry=True)
    try:
        axis = machine["a"]
        await axis.move_by(50.0)  # long enough to be running when the drive dies
        procs[0].kill()
        await wait_until_async(lambda: offline(machine, "a"), timeout=30,
                               what="the axis offline after its drive died")
        assert axis.interrupted is not None
        with pytest.raises(MachineLinkError):
            await axis.position()  # at once, typed
        dropped_at = axis.last_good
        assert dropped_at is not None
        procs.append(start_sim(protocol, port))
        await wait_until_async(lambda: axis.online and not axis.checking, timeout=60,
                               what="the axis online again")
        # the motion was not re-sent: the restarted drive stands where it powered up
        assert abs(await axis.position()) < 0.01
        assert axis.power_lost, "a restarted drive, its motion interrupted, is flagged"
        with pytest.raises(PowerLostError):
            await axis.move_by(1.0)
        await axis.acknowledge()
        assert not axis.power_lost and axis.interrupted is None
        await axis.move_by(1.0, wait=True, timeout=30)
        assert abs(await axis.position() - 1.0) < 0.01
        last_good = axis.last_good
        assert last_good is not None and last_good > dropped_at
    finally:
        await machine.close()


def test_servobus_ack_tells_what_the_drive_shows(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from servobus.cli.main import main

    monkeypatch.delenv("SERVOBUS_MACHINE", raising=False)
    monkeypatch.delenv("SERVOBUS_URL", raising=False)
    text = machine_rig.MIXED + '\n[axes.d]\nurl = "sim://enip"\nunit = "rev"\n'
    path = str(write_machine(tmp_path, text))
    seen = {}
    for name in ("x", "d"):
        with pytest.raises(SystemExit) as info:
            main(["--machine", path, "--axis", name, "ack", "--json"])
        assert info.value.code in (0, None)
        seen[name] = json.loads(capsys.readouterr().out)
    assert seen["x"]["acknowledged"] and seen["x"]["power_cycle"].startswith("unknown")
    # a fresh virtual DYN5 has just powered up: its memory test cell holds 0, not the token
    assert seen["d"]["power_cycle"].startswith("the drive was power-cycled")
