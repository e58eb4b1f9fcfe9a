"""The drive commands over DYN CAN (``--can virtual:...``): virtual nodes on python-can's
in-process virtual bus, served from a background thread; the CLI runs through CliRunner."""

from __future__ import annotations

import asyncio
import itertools
import json
import threading
from collections.abc import Iterator

import pytest
from click.testing import CliRunner, Result

from servobus.cli.main import cli
from servobus.families.dmm import params as P
from servobus.families.dmm import units as U
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.protocols.dyncan.server import serve
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.wall_clock import RealtimeClock
from servobus.transport.can_bus import AsyncCanBus

_channels = itertools.count()


@pytest.fixture
def can_bus() -> Iterator[str]:
    """``virtual:CHANNEL`` with drives 1 and 3 on it; the server stops when the test ends."""
    spec = f"virtual:servobus-cli-can-{next(_channels)}"
    loop = asyncio.new_event_loop()
    ready = threading.Event()
    stop: asyncio.Event | None = None

    async def main() -> None:
        nonlocal stop
        stop = asyncio.Event()
        network = DynCanNetwork([VirtualDrive(1), VirtualDrive(3)])
        port = await AsyncCanBus.open(spec)
        ready.set()
        try:
            await serve(network, port, clock=RealtimeClock(network.drives), stop=stop)
        finally:
            await port.close()

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),), daemon=True)
    thread.start()
    assert ready.wait(10)
    yield spec
    assert stop is not None
    loop.call_soon_threadsafe(stop.set)
    thread.join(10)
    loop.close()


def invoke(*args: str) -> Result:
    # Reads get a roomy 2 s deadline unless the test sets one: the default 50 ms ran out on
    # a loaded machine; deadlines are tested elsewhere.
    roomy = [] if "--timeout" in args else ["--timeout", "2"]
    result = CliRunner().invoke(cli, [*roomy, *args])
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result


def test_status_params_set_over_can(can_bus: str) -> None:
    result = invoke("--can", can_bus, "--id", "1", "--json", "status")
    doc = json.loads(result.stdout)
    assert doc["protocol"] == "dyncan" and doc["drive_id"] == 1 and doc["in_position"] is True
    result = invoke("--can", can_bus, "--id", "3", "--json", "params")
    params = json.loads(result.stdout)["params"]  # all DYN CAN reaches: the 8 and line_num
    assert params == {n: P.spec(n).default for n in (*P.DYN_PARAMS, "line_num")}
    result = invoke("--can", can_bus, "--id", "3", "--json", "set", "max_accel", "60")
    assert json.loads(result.stdout)["new"] == 60


def test_move_and_scan_over_can(can_bus: str) -> None:
    result = invoke("--can", can_bus, "--id", "1", "--json", "move", "--wait", "-4096")
    window = U.onrange_to_counts(P.spec("on_range").default)  # "on position" = inside OnRange
    assert abs(json.loads(result.stdout)["position"] - (-4096)) <= window  # counts
    result = invoke("--can", can_bus, "--id", "1", "--json", "move", "--wait", "-0.25rev")
    assert abs(json.loads(result.stdout)["position"] - (-16384)) <= window
    result = invoke("--can", can_bus, "--json", "scan", "--last", "5", "--per-id", "0.05")
    assert json.loads(result.stdout) == [1, 3]
