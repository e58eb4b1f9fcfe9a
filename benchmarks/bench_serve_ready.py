"""Time to ``ready`` of ``servobus serve`` on the built-in machine, and what importing the
DI, IA and Robotics NodeSets costs of it (issue 36; target 3 s on a 2-core laptop).

``python -m benchmarks serve_ready``: the median of three starts from process start to
the ``ready`` line, then the NodeSet import alone in this process (asyncua's own start
first, not counted).
"""

from __future__ import annotations

import asyncio
import os
import statistics
import subprocess
import sys
import time

from benchmarks.verdict import mark

STARTS = 3


def one_start() -> float:
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "serve", "--opcua",
                             "opc.tcp://127.0.0.1:0"], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if "ready" in line:
                return time.perf_counter() - start
        raise RuntimeError(f"servobus serve ended before ready (exit {proc.wait()})")
    finally:
        proc.terminate()
        proc.wait(30)


async def import_cost() -> tuple[float, float]:
    from asyncua import Server

    from servobus.gateway import opcua_nodesets

    server = Server()
    start = time.perf_counter()
    await server.init()
    init = time.perf_counter() - start
    await opcua_nodesets.import_nodesets(server)
    assert opcua_nodesets.import_seconds is not None
    return init, opcua_nodesets.import_seconds


def main() -> None:
    load = os.getloadavg()[0]
    print(f"serve ready: `servobus serve --opcua opc.tcp://127.0.0.1:0` (built-in machine), "
          f"{STARTS} starts; load average {load:.1f} on {os.cpu_count()} CPUs")
    times = [one_start() for _ in range(STARTS)]
    median = statistics.median(times)
    print(f"  process start -> ready: median {median:.2f} s "
          f"{mark('serve: time to ready, s', median, at_most=3.0, show='{:g} s'.format)}"
          f"  (each: {', '.join(f'{t:.2f}' for t in times)} s)")
    init, nodesets = asyncio.run(import_cost())
    print(f"  of which asyncua's standard address space {init:.2f} s, the DI/IA/Robotics "
          f"NodeSets {nodesets:.2f} s (in this process)")


if __name__ == "__main__":
    main()
