"""Safety: how far and how long a motor runs on after the owner of its motion dies (issue 27).

For each protocol, a virtual drive in its own process (``servobus sim ...``, paced like the
real wire) and an *owner*: a small Python process that holds a constant speed through the
machine API over the drive's URL (a lease renewed every 0.2 s, ttl 0.5 s; the CLI's
``servobus speed`` does the same). Once the motor cruises, the owner is killed with SIGKILL
at a random phase of its renewals; this process, a separate client of the drive, reads the
position just before the kill and polls until the motor rests. Figures per protocol:
time from the death to standstill and distance run after it, p50 / p99 over the runs,
against the documented bound ``lead + v x STREAM_S`` (lead = v^2/(2a) + v x STREAM_S at the
drive's own profile acceleration ``a``; docs/safety.md).

Run: ``python -m benchmarks safety`` (5 runs per protocol, idle), options after it:
``--runs N`` and ``--hogs`` (two CPU-bound processes beside the run), e.g.
``python -m benchmarks safety --runs 20 --hogs`` or ``python -m benchmarks.bench_safety``.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from benchmarks.verdict import mark
from servobus.axis import connect
from servobus.axis.sync import Axis
from servobus.machine.lease import STREAM_S, lead

SERVOBUS = [sys.executable, "-m", "servobus"]
RPM = 600  # a typical jog/constant speed: 10 rev/s
RUNS = 5
SAFETY_NET_S = "900"  # --duration of each simulator: the benchmark stops it
#: Cruise this long after the owner started before the kill (the motor at speed).
CRUISE_S = 0.5

#: protocol -> (simulator arguments, URL prefix of what it prints, drive id for the URL)
SIMS: dict[str, tuple[list[str], str, int | None]] = {
    "dyn232": (["sim", "dyn232", "--listen", "tcp://127.0.0.1:0", "--ids", "1"],
               "dyn232+socket://", 1),
    "dyncan": (["sim", "dyncan", "--socketcand", "127.0.0.1:0", "--ids", "1"],
               "dyncan+socketcand://", 1),
    "enip": (["sim", "enip", "--listen", "127.0.0.1", "--tcp-port", "0", "--udp-port", "0"],
             "enip://", None),
    "easycan": (["sim", "easycan", "--socketcand", "127.0.0.1:0", "--ids", "1"],
                "easycan+socketcand://", 1),
    "modbus": (["sim", "modbus", "--listen", "tcp://127.0.0.1:0", "--ids", "1"],
               "modbus+socket://", 1),
}

#: The owner: holds a constant speed on the drive as a lease until it is killed.
OWNER = """
import sys, time
from servobus.machine import open_url_machine
url, drive, rpm = sys.argv[1], sys.argv[2], float(sys.argv[3])
machine = open_url_machine(url, (None if drive == "-" else int(drive),))
axis = next(iter(machine.axes.values()))
axis.turn(axis.core.scale.from_rpm(rpm), owner="bench owner", ttl=0.5)
lease = axis.lease
print("holding", flush=True)
while axis.renew("bench owner", 0.5):
    time.sleep(0.2)
print(f"the lease ended before the kill: {lease.ended if lease else '?'}", flush=True)
"""


#: Why owners' leases ended before their kill (a run that measured nothing), per protocol.
LOST: dict[str, list[str]] = {}


@dataclass
class Run:
    seconds: float  # from the death to the first sample of the final rest
    counts: int  # distance from the last read before the death to the rest


@contextmanager
def cpu_hogs(count: int) -> Iterator[None]:
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
             for _ in range(count)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait(10)


@contextmanager
def simulator(protocol: str) -> Iterator[str]:
    args, prefix, _ = SIMS[protocol]
    proc = subprocess.Popen([*SERVOBUS, *args, "--duration", SAFETY_NET_S],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()
        if not line.startswith("listening on "):
            raise RuntimeError(f"servobus sim {protocol} printed {line!r}")
        words = line.split()  # listening on tcp://H:P | socketcand H:P | enip://H:P (...)
        where = words[3] if words[2] == "socketcand" else words[2]
        yield prefix + where.split("://", 1)[-1]
    finally:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def one_run(protocol: str, url: str, drive: int | None, watcher: Axis) -> Run | None:
    """One owner, killed while it cruises; None when its lease ended before the kill."""
    owner = subprocess.Popen([sys.executable, "-c", OWNER, url,
                              "-" if drive is None else str(drive), str(RPM)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert owner.stdout is not None
        if owner.stdout.readline().strip() != "holding":
            raise RuntimeError(f"the owner did not start: {owner.communicate()[1][-500:]}")
        time.sleep(CRUISE_S + random.uniform(0, STREAM_S))  # the cruise, at a random phase
        if owner.poll() is not None:
            LOST.setdefault(protocol, []).append(owner.communicate()[0].strip()[-200:])
            return None
        first = watcher.position()  # the last position read while the owner lives
        owner.send_signal(signal.SIGKILL)
        dead = time.monotonic()
        owner.wait(10)
        samples = [(time.monotonic(), watcher.position())]
        while len(samples) < 4 or len({p for _, p in samples[-4:]}) > 1:
            time.sleep(0.01)  # polling the drive: nothing reports the rest
            samples.append((time.monotonic(), watcher.position()))
            if time.monotonic() - dead > 30:
                raise RuntimeError("the motor did not come to rest within 30 s")
        rest = samples[-1][1]
        settled = next(t for t, p in samples if p == rest)
        return Run(settled - dead, rest - first)
    finally:
        if owner.poll() is None:
            owner.kill()
        owner.communicate()


def quantile(values: list[float], q: int) -> float:
    if len(values) == 1:
        return values[0]
    return statistics.quantiles(values, n=100, method="inclusive")[q - 1]


def measure(protocol: str, runs: int, hogs: int) -> None:
    _, _, drive = SIMS[protocol]
    with simulator(protocol) as url, connect(url, drive_id=drive) as watcher:
        cpr = watcher.counts_per_rev
        profile = watcher.stream_profile()
        results = [one_run(protocol, url, drive, watcher) for _ in range(runs)]
    done = [r for r in results if r is not None]
    v = RPM * cpr / 60
    a = profile.accel_rpm_s * cpr / 60
    the_lead = lead(v, a)
    bound = the_lead + v * STREAM_S
    where = f"{protocol}, {'beside 2 CPU hogs' if hogs else 'idle'}"
    if not done:
        print(f"  {protocol:8s} every owner's lease ended before its kill ({runs} runs)")
        return
    times = [r.seconds * 1000 for r in done]
    revs = [r.counts / cpr for r in done]
    lost = f", {runs - len(done)} lease(s) ended before the kill" if len(done) < runs else ""
    print(f"  {protocol:8s} to rest p50 {quantile(times, 50):5.0f} / p99 {quantile(times, 99):5.0f}"
          f" ms   distance p50 {quantile(revs, 50):5.3f} / p99 {quantile(revs, 99):5.3f} rev   "
          f"bound {bound / cpr:5.3f} rev (lead {the_lead / cpr:.3f} at "
          f"{profile.accel_rpm_s:.0f} rpm/s){lost}   "
          + mark(f"safety: p99 distance after the owner's death, {where} (rev)",
                 quantile(revs, 99), at_most=bound / cpr, show=lambda x: f"{x:.3f} rev"))
    for why in LOST.get(protocol, []):
        print(f"    {why}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks safety")
    parser.add_argument("--runs", type=int, default=RUNS, help="owners killed per protocol")
    parser.add_argument("--hogs", action="store_true", help="two CPU-bound processes beside")
    options, _ = parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    hogs = 2 if options.hogs else 0
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"safety: an owner holding {RPM} rpm killed with SIGKILL, {options.runs} run(s) per "
          f"protocol, {hogs} CPU hog(s), load {load:.2f}; time and distance from its death "
          "to standstill (p50 / p99) against lead + v x STREAM_S")
    with cpu_hogs(hogs):
        for protocol in SIMS:
            try:
                measure(protocol, options.runs, hogs)
            except Exception as exc:  # one protocol that cannot run; the others still do
                print(f"  {protocol:8s} ERROR {type(exc).__name__}: {str(exc)[-300:]}")


if __name__ == "__main__":
    from benchmarks.verdict import summary

    main()
    print(summary())
