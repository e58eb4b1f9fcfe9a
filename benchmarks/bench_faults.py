"""Faults: links that fail under a running machine, and what the machine makes of them (issue 29).

For each protocol a virtual drive in its own process (``servobus sim ...``, paced like its
wire) behind a TCP proxy of this process (benchmarks/fault_proxy.py: a serial-to-Ethernet
bridge, a CAN gateway, a switch), and one machine of five axes - one per protocol, each on
its proxy - in a process of its own (benchmarks/fault_host.py): ``open_machine_async(...,
retry=True)``, every axis read every 0.1 s as the GUI and the gateway poll. Faults are
injected one at a time, each kind on each protocol in a shuffled order, round after round
until ``--seconds`` have passed (:data:`KINDS`):

* ``drive restart``: the drive's process is killed (SIGKILL) and started again on the same
  port after 2-4 s (a drive's power cycle; a DMM drive takes that long to boot);
* ``bridge restart``: the proxy stops - every connection gone, nothing listening - and
  listens again after 0.5-2 s (a serial-to-Ethernet bridge or gateway that reboots);
* ``dropped connections``: the proxy aborts its established connections (RST to both
  sides) and keeps listening.

After each fault the machine process waits for the axis to serve a fresh value, then
acknowledges what the axis flags (power loss, interrupted motion), moves it to a new
absolute target and reads until it rests there (a read that misses its deadline on a
loaded host is read again, as the CLI's ``move --wait`` does). Figures:

* faults injected and survived: online again within :data:`RECOVER_S` and the move after
  acknowledge reached its target (within :data:`TOLERANCE_REV`);
* time to recover, p50 / p99: from the moment the link is available again (the drive's
  process listens again, the proxy listens again, the connections were cut) to the first
  fresh value - a position read that started after that moment and returned (the machine's
  backoff, reconnect and power check included);
* values served stale: reads (the poller's ``readings()``) that started after the fault made
  the drive unreachable (its process reaped, the proxy stopped, the connections cut) and
  returned a value before the link was available again. Nothing could answer them: any
  value they returned was old. Target 0;
* motion commands re-sent: the proxies decode what the machine sends (servobus.sniff) and
  count the frames that start a move; every move of the run goes to a new absolute target,
  so a motion frame seen twice was sent twice. Target 0;
* power loss flagged after drive restarts (every one should be: DYN5 by its memory-test
  token, the others by the position jump) and after the other faults (none should be);
* servobus log lines per fault (one per state change: down, online, flagged, acknowledged);
* CPU of the machine process, % of one core, over :data:`IDLE_S` with every link up and over
  as long with every proxy stopped (nothing listening anywhere): a reconnect backoff that
  spins shows up in the second.

Then the gateway's faults of issue 30 (benchmarks/fault_gateway.py, the kinds in
benchmarks/faults_hostile.py): a real ``servobus serve`` on the built-in virtual machine
(OPC UA with a users file, MQTT with ``--mqtt-commands`` through a Mosquitto broker on a free
port; without Mosquitto the MQTT part is skipped in one line) takes 10,000 hostile MQTT
payloads, an OPC UA session flood and a login flood, one line each of what it did; then an
OPC UA read and an MQTT state message must still arrive, and it is stopped with Ctrl-C.
The gateway answers about 90 commands a second on the loaded 2-core machine: the 10,000
payloads take about 2 minutes.

Run: ``python -m benchmarks faults`` (3 minutes of faults, then 2 x 10 s of CPU, then about
2.5 minutes of the gateway's faults), options after it: ``--seconds S``, ``--idle-seconds
S``, ``--seed N``, ``--logs DIR`` (keep the processes' logs), ``--only link|hostile|mqtt|
sessions|logins`` (repeatable: the link faults, all of the gateway's, or one of them),
``--hostile-count N`` (hostile MQTT payloads); or ``python -m benchmarks.bench_faults``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import random
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchmarks import fault_gateway
from benchmarks.fault_gateway import HOSTILE_COUNT, expected_time, print_hostile, run_hostile
from benchmarks.fault_proxy import MotionTap, Proxy
from benchmarks.verdict import mark, percent
from servobus.machine.machine import RETRY_MAX_S

ROOT = Path(__file__).resolve().parents[1]
SECONDS = 180.0
IDLE_S = 10.0
SEED = 29
RECOVER_S = 30.0
TOLERANCE_REV = 0.01
#: Each move goes to a new absolute target: FIRST_TARGET_REV + STEP_REV x n.
FIRST_TARGET_REV = 0.25
STEP_REV = 0.05
#: p99 target of the time to recover: the backoff's longest wait plus a second for the
#: connection, the power check and the first read.
RECOVER_TARGET_S = RETRY_MAX_S + 1.0
#: A machine process waiting for five links with nothing listening, polled at 10 Hz, spends
#: at most this share of one core (a backoff that spins takes all of it).
CPU_TARGET_PERCENT = 5.0
SAFETY_NET_S = "3600"  # --duration of each simulator: the run stops it

#: protocol -> (``servobus sim`` arguments, drive URL); {port} is the drive's or proxy's.
SIMS: dict[str, tuple[list[str], str]] = {
    "dyn232": (["dyn232", "--listen", "tcp://127.0.0.1:{port}", "--ids", "1"],
               "dyn232+socket://127.0.0.1:{port}"),
    "dyncan": (["dyncan", "--socketcand", "127.0.0.1:{port}", "--ids", "1"],
               "dyncan+socketcand://127.0.0.1:{port}"),
    "easycan": (["easycan", "--socketcand", "127.0.0.1:{port}", "--ids", "1"],
                "easycan+socketcand://127.0.0.1:{port}"),
    "enip": (["enip", "--tcp-port", "{port}", "--udp-port", "0"], "enip://127.0.0.1:{port}"),
    "modbus": (["modbus", "--listen", "tcp://127.0.0.1:{port}", "--ids", "1"],
               "modbus+socket://127.0.0.1:{port}"),
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass(frozen=True)
class Window:
    """A fault's times (``time.monotonic()``): from ``t0`` nothing could answer; from ``t1``
    the link is available again (``t0 == t1``: an instant, e.g. cut connections)."""

    t0: float
    t1: float


class Link:
    """One protocol's drive process, its proxy and the machine axis on it."""

    def __init__(self, protocol: str, logs: Path) -> None:
        self.protocol = protocol
        self.drive_port = free_port()
        self.tap = MotionTap(protocol)
        self.proxy = Proxy(free_port(), self.drive_port, self.tap)
        self.sim: asyncio.subprocess.Process | None = None
        self._drain: asyncio.Task[None] | None = None
        self.log = logs / f"sim-{protocol}.log"
        self.moves = 0

    @property
    def url(self) -> str:
        return SIMS[self.protocol][1].format(port=self.proxy.port)

    def next_target(self) -> float:
        self.moves += 1
        return FIRST_TARGET_REV + STEP_REV * self.moves

    async def start_sim(self) -> None:
        args = [a.format(port=self.drive_port) for a in SIMS[self.protocol][0]]
        with self.log.open("a") as err:
            self.sim = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "servobus", "sim", *args, "--duration", SAFETY_NET_S,
                stdout=asyncio.subprocess.PIPE, stderr=err)
        assert self.sim.stdout is not None
        while True:
            line = (await self.sim.stdout.readline()).decode()
            if not line:
                raise RuntimeError(f"servobus sim {self.protocol} ended: see {self.log}")
            if line.startswith("listening on"):
                break
        self._drain = asyncio.ensure_future(self._drain_output(self.sim.stdout))

    @staticmethod
    async def _drain_output(stream: asyncio.StreamReader) -> None:
        while await stream.read(4096):
            pass

    async def kill_sim(self) -> None:
        sim, self.sim = self.sim, None
        if sim is not None and sim.returncode is None:
            sim.kill()
            await sim.wait()
        if self._drain is not None:
            with contextlib.suppress(BaseException):
                await self._drain


# ------------------------------------------------------------------ fault kinds
Inject = Callable[[Link, random.Random], Awaitable[Window]]


@dataclass(frozen=True)
class FaultKind:
    """One kind of fault: ``inject`` makes it happen on a target and says when."""

    name: str
    inject: Inject
    applies: Callable[[Link], bool] = lambda link: True


async def drive_restart(link: Link, rng: random.Random) -> Window:
    await link.kill_sim()
    t0 = time.monotonic()
    await asyncio.sleep(rng.uniform(2.0, 4.0))  # the drive boots (the fault's own time)
    await link.start_sim()
    return Window(t0, time.monotonic())


async def bridge_restart(link: Link, rng: random.Random) -> Window:
    await link.proxy.stop()
    t0 = time.monotonic()
    await asyncio.sleep(rng.uniform(0.5, 2.0))  # the bridge reboots
    await link.proxy.start()
    return Window(t0, time.monotonic())


async def dropped_connections(link: Link, rng: random.Random) -> Window:
    link.proxy.cut()
    t = time.monotonic()
    return Window(t, t)


KINDS: list[FaultKind] = [
    FaultKind("drive restart", drive_restart),
    FaultKind("bridge restart", bridge_restart),
    FaultKind("dropped connections", dropped_connections),
]


# ------------------------------------------------------------------ the machine process
class HostProcess:
    """benchmarks/fault_host.py in its own process; :meth:`ask` one question at a time."""

    def __init__(self, proc: asyncio.subprocess.Process) -> None:
        self.proc = proc

    @classmethod
    async def start(cls, machine_file: Path, log: Path, debug: bool
                    ) -> tuple[HostProcess, list[str]]:
        args = [str(machine_file), *(["--debug"] if debug else [])]
        with log.open("a") as err:
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "benchmarks.fault_host", *args, cwd=ROOT,
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE, stderr=err)
        host = cls(proc)
        ready = await host._answer()
        return host, list(ready["ready"])

    async def _answer(self) -> dict[str, Any]:
        assert self.proc.stdout is not None
        line = await self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the machine process ended")
        answer: dict[str, Any] = json.loads(line)
        return answer

    async def ask(self, cmd: str, **fields: Any) -> dict[str, Any]:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"cmd": cmd, **fields}).encode() + b"\n")
        await self.proc.stdin.drain()
        return await self._answer()

    async def recover(self, axis: str, since: float, target: float) -> dict[str, Any]:
        """The axis's first fresh value after ``since``, then a move to ``target``."""
        return await self.ask("recover", axis=axis, since=since, timeout=RECOVER_S,
                              tolerance=TOLERANCE_REV, target=target)

    async def cpu_share(self, seconds: float) -> float:
        """CPU of the machine process over ``seconds``, as a share of one core."""
        a = await self.ask("cpu")
        await asyncio.sleep(seconds)
        b = await self.ask("cpu")
        return float((b["cpu"] - a["cpu"]) / (b["t"] - a["t"]))

    async def quit(self) -> None:
        assert self.proc.stdin is not None
        with contextlib.suppress(OSError):
            self.proc.stdin.write(b'{"cmd": "quit"}\n')
            await self.proc.stdin.drain()
        try:
            await asyncio.wait_for(self.proc.wait(), 30)
        except TimeoutError:
            self.proc.kill()
            await self.proc.wait()


# ------------------------------------------------------------------ one fault
@dataclass
class Outcome:
    kind: str
    protocol: str
    survived: bool
    recover_s: float | None
    stale: int
    power_lost: bool
    log_lines: int
    error: str | None = None


async def one_fault(host: HostProcess, kind: FaultKind, link: Link,
                    rng: random.Random) -> Outcome:
    before = await host.ask("stats")
    window = await kind.inject(link, rng)
    target = link.next_target()
    got = await host.recover(link.protocol, window.t1, target)
    stale = (await host.ask("stale", axis=link.protocol, t0=window.t0, t1=window.t1))["stale"]
    after = await host.ask("stats")
    error = got.get("error")
    if error is None and abs(got["position"] - target) > TOLERANCE_REV:
        error = f"the move to {target:g} rev ended at {got['position']:g} rev"
    online_at = got.get("online_at")
    return Outcome(kind.name, link.protocol, error is None,
                   None if online_at is None else online_at - window.t1, stale,
                   bool(got.get("power_lost")), after["log_lines"] - before["log_lines"], error)


# ------------------------------------------------------------------ the run
@dataclass
class Report:
    outcomes: list[Outcome] = field(default_factory=list)
    motion_frames: int = 0
    moves: int = 0
    resent: int = 0
    cpu_up: float = 0.0
    cpu_down: float = 0.0
    back_after_idle: list[str] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)


def machine_text(links: dict[str, Link]) -> str:
    return "".join(f'[axes.{p}]\nurl = "{link.url}"\nid = 1\nunit = "rev"\n\n'
                   for p, link in links.items())


async def run(seconds: float, idle_s: float, seed: int, logs: Path, debug: bool = False
              ) -> Report:
    links = {p: Link(p, logs) for p in SIMS}
    report = Report()
    host: HostProcess | None = None
    try:
        for link in links.values():
            await link.start_sim()
            await link.proxy.start()
        path = logs / "machine.toml"
        path.write_text(machine_text(links), encoding="utf-8")
        host, ready = await HostProcess.start(path, logs / "machine.log", debug)
        if sorted(ready) != sorted(links):
            raise RuntimeError(f"only {ready} online at start; see {logs}")
        for link in links.values():  # away from the power-up position (0): a restart shows
            got = await host.recover(link.protocol, time.monotonic(), link.next_target())
            if got.get("error") is not None:
                raise RuntimeError(f"{link.protocol}: the first move failed: {got['error']}")
        rng = random.Random(seed)
        pairs = [(kind, link) for kind in KINDS for link in links.values()
                 if kind.applies(link)]
        end = time.monotonic() + seconds
        while not report.outcomes or time.monotonic() < end:
            rng.shuffle(pairs)
            for kind, link in pairs:
                if report.outcomes and time.monotonic() >= end:
                    break
                report.outcomes.append(await one_fault(host, kind, link, rng))
        report.cpu_up = await host.cpu_share(idle_s)
        for link in links.values():
            await link.proxy.stop()
        report.cpu_down = await host.cpu_share(idle_s)
        for link in links.values():
            await link.proxy.start()
        for link in links.values():
            got = await host.recover(link.protocol, time.monotonic(), link.next_target())
            if got.get("error") is None:
                report.back_after_idle.append(link.protocol)
        report.stats = await host.ask("stats")
    finally:
        if host is not None:
            await host.quit()
        for link in links.values():
            await link.proxy.close()
            await link.kill_sim()
    report.motion_frames = sum(link.tap.frames for link in links.values())
    report.resent = sum(link.tap.resent for link in links.values())
    report.moves = sum(link.moves for link in links.values())
    return report


# ------------------------------------------------------------------ printing
def quantile(values: list[float], q: int) -> float:
    if len(values) == 1:
        return values[0]
    return statistics.quantiles(values, n=100, method="inclusive")[q - 1]


def p50_p99(values: list[float]) -> str:
    if not values:
        return "       -"
    ms = [v * 1000 for v in values]
    return f"p50 {quantile(ms, 50):5.0f} / p99 {quantile(ms, 99):5.0f} ms"


def print_report(r: Report, idle_s: float) -> None:
    out = r.outcomes
    for protocol in SIMS:
        for kind in KINDS:
            mine = [o for o in out if o.protocol == protocol and o.kind == kind.name]
            if not mine:
                continue
            survived = sum(o.survived for o in mine)
            times = [o.recover_s for o in mine if o.recover_s is not None]
            flagged = sum(o.power_lost for o in mine)
            print(f"  {protocol:8s} {kind.name:20s} survived {survived:2d}/{len(mine):<2d}  "
                  f"recover {p50_p99(times)}  power loss flagged {flagged}/{len(mine)}")
            for o in mine:
                if o.error:
                    print(f"    {o.kind}: {o.error[-300:]}")
    survived = sum(o.survived for o in out)
    print(f"  faults injected {len(out)}, survived {survived}   "
          + mark("faults: share of faults survived", survived / len(out), at_least=1.0,
                 show=percent))
    times = [o.recover_s for o in out if o.recover_s is not None]
    if times:
        p99 = quantile(times, 99)
        print(f"  time to recover (link available again -> first fresh value) "
              f"{p50_p99(times)}   "
              + mark("faults: p99 time to recover (s)", p99, at_most=RECOVER_TARGET_S,
                     show=lambda s: f"{s:g} s"))
    stale = sum(o.stale for o in out)
    print(f"  values served stale (reads started after the drive became unreachable that "
          f"returned a value before it was back) {stale}   "
          + mark("faults: values served stale", stale, at_most=0))
    print(f"  motion commands re-sent {r.resent} ({r.motion_frames} motion frames on the "
          f"wire for {r.moves} moves commanded)   "
          + mark("faults: motion commands re-sent", r.resent, at_most=0))
    restarts = [o for o in out if o.kind == "drive restart"]
    others = [o for o in out if o.kind != "drive restart"]
    flagged = sum(o.power_lost for o in restarts)
    if restarts:
        print(f"  power loss flagged after drive restarts {flagged}/{len(restarts)}   "
              + mark("faults: drive restarts flagged as power loss", flagged / len(restarts),
                     at_least=1.0, show=percent)
              + f"; after other faults {sum(o.power_lost for o in others)}/{len(others)}")
    lines = [o.log_lines for o in out]
    print(f"  servobus log lines per fault: mean {statistics.fmean(lines):.1f}, max "
          f"{max(lines)} (one per state change: down, online, power loss, acknowledged)")
    print(f"  CPU of the machine process over {idle_s:g} s: {r.cpu_up * 100:.1f} % of one core "
          f"with every link up, {r.cpu_down * 100:.1f} % with nothing listening on any link   "
          + mark("faults: CPU of the machine process with nothing listening, % of one core",
                 r.cpu_down * 100, at_most=CPU_TARGET_PERCENT, show="{:g} %".format))
    missing = sorted(set(SIMS) - set(r.back_after_idle))
    print(f"  back after the {idle_s:g} s with nothing listening: "
          f"{', '.join(r.back_after_idle) or 'none'}"
          + (f"; NOT back: {', '.join(missing)}" if missing else ""))
    reads = r.stats.get("reads", {})
    print(f"  machine process: {r.stats.get('reconnect_tries', 0)} reconnect tries, "
          f"{r.stats.get('log_lines', 0)} log lines, reads {reads}")


#: What ``--only`` selects: the link faults, the gateway's (all three), or one of those.
ONLY = {"link": ["link"], "hostile": list(fault_gateway.KINDS),
        **{kind: [kind] for kind in fault_gateway.KINDS}}


def selected(only: list[str] | None) -> list[str]:
    """The parts to run, in the run's order: ``link`` first, then the gateway's kinds."""
    chosen = {part for name in (only or ["link", "hostile"]) for part in ONLY[name]}
    return [part for part in ("link", *fault_gateway.KINDS) if part in chosen]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks faults")
    parser.add_argument("--seconds", type=float, default=SECONDS,
                        help="inject faults for this long (at least one)")
    parser.add_argument("--idle-seconds", type=float, default=IDLE_S,
                        help="each CPU measurement's length")
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--logs", type=Path, help="keep the processes' logs in this directory "
                        "(the machine's with its debug lines: every reconnect try)")
    parser.add_argument("--only", action="append", choices=list(ONLY),
                        help="run only these (repeatable): the link faults, the gateway's "
                        "hostile kinds, or one of those; default: all")
    parser.add_argument("--hostile-count", type=int, default=HOSTILE_COUNT,
                        help="hostile MQTT payloads (the gateway answers about 90 a second)")
    options, _ = parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    parts = selected(options.only)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with tempfile.TemporaryDirectory(prefix="servobus-faults-") as tmp:
        logs = options.logs or Path(tmp)
        logs.mkdir(parents=True, exist_ok=True)
        if "link" in parts:
            print(f"faults: drive restarts, bridge restarts and dropped connections on "
                  f"{', '.join(SIMS)} (paced virtual drives behind TCP proxies) for "
                  f"{options.seconds:g} s under a machine (retry=True) polling every axis "
                  f"every 0.1 s in its own process; seed {options.seed}, load {load:.2f}")
            report = asyncio.run(run(options.seconds, options.idle_seconds, options.seed,
                                     logs, debug=options.logs is not None))
            print_report(report, options.idle_seconds)
            print()
        kinds = [part for part in parts if part != "link"]
        if kinds:
            print(hostile_header(kinds, options.hostile_count, options.seed))
            print_hostile(asyncio.run(run_hostile(kinds, options.hostile_count,
                                                  options.seed, logs)))


def hostile_header(kinds: list[str], count: int, seed: int) -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    what = {"mqtt": f"{count} hostile MQTT payloads (the gateway answers about 90 a second "
                    f"here: {expected_time(count)})",
            "sessions": "an OPC UA session flood", "logins": "a login flood"}
    return (f"faults of the gateway: {', '.join(what[k] for k in kinds)} against servobus "
            f"serve in its own process (built-in virtual machine; OPC UA with a users file; "
            f"MQTT commands through Mosquitto when installed); seed {seed}, load {load:.2f}")


if __name__ == "__main__":
    from benchmarks.verdict import summary

    main()
    print(summary())
