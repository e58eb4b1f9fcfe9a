"""A gateway that owns its process freezes its start-up heap out of the collector's scans
(servobus.gateway.heap); one inside another program's process leaves the collector alone.

In a child process: freezing is process-wide, and pytest's heap is not ours to freeze."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SCRIPT = """
import asyncio, gc, json
from fake_machine import FakeMachine
from servobus.gateway.opcua_server import OpcUaOptions
from servobus.gateway.serve import Gateway, GatewayOptions

async def started(own: bool) -> dict:
    gateway = Gateway(FakeMachine(), GatewayOptions(OpcUaOptions("opc.tcp://127.0.0.1:0"),
                                                    own_process=own))
    await gateway.start()
    try:
        return {"frozen": gc.get_freeze_count(), "scanned": len(gc.get_objects())}
    finally:
        await gateway.close()

guest = asyncio.run(started(False))
owner = asyncio.run(started(True))
print(json.dumps({"guest": guest, "owner": owner}))
"""


def test_only_a_gateway_that_owns_its_process_freezes_the_start_up_heap() -> None:
    here = str(Path(__file__).parent)
    path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)
    proc = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPATH": path})
    assert proc.returncode == 0, proc.stderr
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert seen["guest"]["frozen"] == 0
    # asyncua's address space alone is a few hundred thousand objects; after the freeze a
    # full collection scans only what was made since
    assert seen["owner"]["frozen"] > 100_000
    assert seen["owner"]["scanned"] < seen["owner"]["frozen"] // 10


CYCLES = """
import gc, json, weakref
from servobus.gateway.heap import collector_off, freeze_startup_heap

class Node:
    pass

def cycle() -> weakref.ref:
    a, b = Node(), Node()
    a.other, b.other = b, a
    return weakref.ref(a)

seen = {}
with collector_off():
    seen["off"] = not gc.isenabled()
    off_start = cycle()  # garbage made while the start runs with the collector off
    seen["frozen"] = freeze_startup_heap() > 0
    seen["on_after_freeze"] = gc.isenabled()
gc.collect()
seen["off_start_kept"] = off_start() is not None  # frozen with the rest, as documented
on_start = cycle()  # garbage made with the collector on: collected before a freeze
freeze_startup_heap()
seen["on_start_collected"] = on_start() is None
print(json.dumps(seen))
"""


def test_a_start_with_the_collector_off_freezes_its_garbage_and_turns_it_on() -> None:
    """``servobus serve``'s start (servobus.gateway.heap.collector_off): no full collection
    before the freeze, so the start's garbage is frozen too; the collector is on after."""
    proc = subprocess.run([sys.executable, "-c", CYCLES], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == {
        "off": True, "frozen": True, "on_after_freeze": True, "on_start_collected": True,
        "off_start_kept": True}
