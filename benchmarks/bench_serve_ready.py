"""Time to ``ready`` of ``servobus serve`` on the built-in machine, and what the OPC UA
address space costs of it (issue 36; target 3 s on a 2-core laptop; docs/gateway.md
"Start-up time").

``python -m benchmarks serve_ready``: one start with empty caches (a new installation's
first start, which builds them: its own folder as ``XDG_CACHE_HOME``), one start that is
not counted, then the median of three starts from process start to the ``ready`` line,
each with the CPU time its process had used by then (Linux; on a machine busy with other
work the wall time grows with the load, the CPU time hardly: an idle machine's wall time
is close to it). Python's bytecode of servobus is cached as an installed package's is
(``PYTHONDONTWRITEBYTECODE`` is dropped for the starts: without it every start compiles
servobus's modules anew, about 0.4 s of CPU). Then, in this process, asyncua's standard
address space built from its generated code and loaded from the cache, and the NodeSets
from the cache.
"""

from __future__ import annotations

import asyncio
import gc
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.verdict import mark

STARTS = 3


def one_start(env: dict[str, str] | None = None) -> tuple[float, float | None]:
    """Seconds from process start to ``ready``, and the process's CPU seconds by then."""
    start = time.perf_counter()
    child = {k: v for k, v in (env or os.environ).items() if k != "PYTHONDONTWRITEBYTECODE"}
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "serve", "--opcua",
                             "opc.tcp://127.0.0.1:0"], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, env=child)
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if "ready" in line:
                return time.perf_counter() - start, cpu_seconds(proc.pid)
        raise RuntimeError(f"servobus serve ended before ready (exit {proc.wait()})")
    finally:
        proc.terminate()
        proc.wait(30)


def cpu_seconds(pid: int) -> float | None:
    """User and system CPU of process ``pid`` (all its threads), from /proc; None without."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_text(cpu: float | None) -> str:
    return "CPU n/a" if cpu is None else f"CPU {cpu:.2f} s"


async def address_space_costs() -> tuple[float, float, float]:
    """Seconds: asyncua's standard address space built, then loaded from the cache (the
    collector off, as ``servobus serve`` starts), then the NodeSets from the cache."""
    from asyncua import Server
    from asyncua.server.internal_server import InternalServer

    from servobus.gateway import opcua_cache, opcua_nodesets

    built = InternalServer()
    start = time.perf_counter()
    await built.load_standard_address_space()
    build = time.perf_counter() - start
    loaded = InternalServer()
    gc.disable()
    try:
        start = time.perf_counter()
        await opcua_cache.load_standard(loaded, loaded.load_standard_address_space)
        load = time.perf_counter() - start
    finally:
        gc.enable()
    server = Server()
    await server.init()
    await opcua_nodesets.import_nodesets(server)
    assert opcua_nodesets.import_seconds is not None
    return build, load, opcua_nodesets.import_seconds


def main() -> None:
    load = os.getloadavg()[0]
    print(f"serve ready: `servobus serve --opcua opc.tcp://127.0.0.1:0` (built-in machine); "
          f"load average {load:.1f} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as empty:
        first, first_cpu = one_start({**os.environ, "XDG_CACHE_HOME": empty})
    print(f"  first start (empty caches, builds them): {first:.2f} s, {cpu_text(first_cpu)}")
    one_start()  # the user's caches are there from here on, whatever they held before
    runs = [one_start() for _ in range(STARTS)]
    median = statistics.median(t for t, _ in runs)
    cpus = [c for _, c in runs if c is not None]
    cpu = f"; CPU median {statistics.median(cpus):.2f} s" if cpus else ""
    print(f"  process start -> ready: median {median:.2f} s "
          f"{mark('serve: time to ready, s', median, at_most=3.0, show='{:g} s'.format)}"
          f"  (each: {', '.join(f'{t:.2f}' for t, _ in runs)} s{cpu}; load average now "
          f"{os.getloadavg()[0]:.1f})")
    build, cached, nodesets = asyncio.run(address_space_costs())
    print(f"  asyncua's standard address space: built {build:.2f} s, from the cache "
          f"{cached:.2f} s; the DI/IA/Robotics NodeSets from the cache {nodesets:.2f} s "
          f"(in this process)")


if __name__ == "__main__":
    main()
