"""``kill -9`` of ``servobus serve`` while an OPC UA client holds a SetSpeed (issue 27): the
drives, each a virtual drive in its own process (a DYN5 over EtherNet/IP, a YZ-AIM over
EasyCan through socketcand), come to rest by themselves within the lease's lead of where
they were when the gateway died, inside their soft limits. Read from outside with a
client of this process's own."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import subprocess
import sys
from collections.abc import Awaitable, Iterator
from pathlib import Path

import pytest
from asyncua import Client
from gateway_rig import PASSWORD, USER, axes_of, names, start_gateway, users_file
from rig import wait_until_async
from subprocess_rig import read_line, stop_process

from servobus.machine import AsyncMachine, AsyncMachineAxis, open_machine_async
from servobus.machine.lease import STREAM_S, lead

SIMS = {  # the simulator, the prefix of its address line, the URL that line gives
    "enip": (["enip", "--tcp-port", "0", "--udp-port", "0", "--no-realtime",
              "--reset-downtime", "0.3"], "listening on enip://", "enip://{}"),
    "easycan": (["easycan", "--fast", "--socketcand", "127.0.0.1:0"],
                "listening on socketcand ", "easycan+socketcand://{}"),
}
CELL = """name = "kill-cell"
[axes.z]
url = "{enip}"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-200.0, 200.0]
[axes.c]
url = "{easycan}"
id = 1
unit = "deg"
limits = [-720.0, 720.0]
"""
#: Asked speeds (unit/s), well inside both drives' profiles.
SPEEDS = {"z": 50.0, "c": 360.0}
#: Beyond the lead: the outside reads after the kill come up to this late, in unit.
MARGIN = {"z": 0.05, "c": 1.0}


@contextlib.contextmanager
def sims(*kinds: str) -> Iterator[list[str]]:
    """Virtual drives of these kinds, each in its own process, started at once (gone after
    120 s at the latest); their URLs."""
    procs = [subprocess.Popen([sys.executable, "-m", "servobus", "sim", *SIMS[kind][0],
                               "--duration", "120"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
             for kind in kinds]
    try:
        urls = []
        for kind, proc in zip(kinds, procs, strict=True):
            _, prefix, url = SIMS[kind]
            line = read_line(proc, prefix, timeout=30)
            urls.append(url.format(line.removeprefix(prefix).split()[0]
                                   .removeprefix("enip://")))
        yield urls
    finally:
        for proc in procs:
            stop_process(proc)


@pytest.mark.slow
async def test_a_killed_gateway_leaves_each_drive_at_rest_within_its_lead(
        tmp_path: Path) -> None:
    with sims("enip", "easycan") as (enip, easycan):
        path = tmp_path / "cell.toml"
        path.write_text(CELL.format(enip=enip, easycan=easycan))
        gateway = start_gateway("--machine", str(path), "--users", str(users_file(tmp_path)),
                                "--rate", "20")
        watcher = await open_machine_async(path)  # the outside reader: links of its own
        try:
            await _kill_while_turning(gateway.proc, gateway.endpoint, watcher)
        finally:
            gateway.stop()
            await watcher.close()


async def _kill_while_turning(proc: subprocess.Popen[bytes], endpoint: str,
                              watcher: AsyncMachine) -> None:
    start = {name: await watcher.axes[name].position() for name in SPEEDS}
    client = Client(endpoint)
    client.set_user(USER)
    client.set_password(PASSWORD)
    async with client:
        n = await names(client)
        nodes = await axes_of(client, "kill-cell")

        async def set_speed() -> None:
            for name, speed in SPEEDS.items():
                await nodes[name].call_method(f"{n.servobus}:SetSpeed", speed, 1.0)

        await set_speed()
        for name, speed in SPEEDS.items():  # cruising at the asked speed: renew once more
            axis = watcher.axes[name]
            await wait_until_async(lambda a=axis, v=speed: _near(a.speed(), v), timeout=30,
                                   what=f"{name} cruising at {speed:g}")
        await set_speed()
        proc.send_signal(signal.SIGKILL)  # the gateway dies; the session with it
        at_kill = dict(zip(SPEEDS, await asyncio.gather(
            *(watcher.axes[name].position() for name in SPEEDS)), strict=True))
        for name in SPEEDS:
            axis = watcher.axes[name]
            await wait_until_async(lambda a=axis: _at_rest(a), timeout=30,
                                   what=f"{name} at rest after the kill")
    for name, speed in SPEEDS.items():
        axis = watcher.axes[name]
        profile = await axis.core().stream_profile()
        accel = abs(axis.scale.from_rpm(profile.accel_rpm_s))
        bound = lead(speed, accel) + speed * STREAM_S + MARGIN[name]
        end = await axis.position()
        assert at_kill[name] - start[name] > 0, f"{name} did not move"
        assert end - at_kill[name] <= bound, (
            f"{name} went {end - at_kill[name]:g} {axis.unit} after the kill, more than "
            f"lead {lead(speed, accel):g} + {speed * STREAM_S:g} + {MARGIN[name]:g}")
        assert axis.limits is not None and axis.limits[0] <= end <= axis.limits[1]


async def _near(speed: Awaitable[float], value: float) -> bool:
    return abs(await speed - value) < 0.05 * value


async def _at_rest(axis: AsyncMachineAxis) -> bool:
    """Speed 0, and the position the same before and after reading it."""
    first = await axis.position()
    if await axis.speed() != 0:
        return False
    return await axis.position() == first
