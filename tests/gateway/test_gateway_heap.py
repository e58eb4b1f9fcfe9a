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
