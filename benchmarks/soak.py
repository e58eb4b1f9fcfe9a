"""Soak and abuse run against the virtual drive servers (loopback only, a few minutes).

Run: ``python -m benchmarks.soak`` (everything) or ``python -m benchmarks.soak dyn2 can``
(scenarios whose name contains an argument); ``--seconds N`` sets each attack's length
(default 8). Not part of ``pytest`` (the bounded versions live in tests/test_sim_abuse_*.py)
nor of ``python -m benchmarks``.

Every scenario starts a fresh ``servobus sim`` process, measures its resident memory (VmRSS)
before, at the peak of and after the attack, and runs a well-behaved client (one status read
every 20 ms, each with a deadline) beside the attacker. A scenario passes when the server
is alive, its memory stays within ``RSS_BOUND_MIB`` of the start, and the well-behaved
client met every deadline. Exit status 1 when any scenario fails.

The ``enip`` scenarios (issue 17.5) measure a polite EtherNet/IP originator (one parameter
read at a time) beside two flooders of valid requests that read their replies ("greedy") or
never do; its deadline is the target, ``ENIP_TARGET_S`` (100 ms), and its worst reply time
is printed.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from benchmarks import soak_clients as sc

RSS_BOUND_MIB = 64.0  # growth allowed under any attack
DEADLINE_S = {"fast": 0.25, "paced": 0.5}  # the well-behaved client's deadline per reply
ENIP_TARGET_S = 0.1  # issue 17.5: the polite originator's worst reply beside a flooder
PROBERS: dict[str, Callable[..., sc.Latency]] = {
    "dyn2": sc.dyn2_prober, "can": sc.can_prober, "enip": sc.enip_prober}
CONNECTIONS = 2000
STATE_MUTATIONS = 20_000  # random corruptions of a valid state file, checked in-process
STATE_FILES = 200  # ... of which this many also go through a real file (open, lock, refuse)


@dataclass
class Result:
    name: str
    rss_before: float
    rss_peak: float
    rss_after: float
    probe: sc.Latency | None
    alive: bool
    note: str = ""

    @property
    def ok(self) -> bool:
        probe_ok = self.probe is None or (self.probe.misses == 0 and bool(self.probe.samples))
        return self.alive and self.rss_peak - self.rss_before <= RSS_BOUND_MIB and probe_ok

    def line(self) -> str:
        if not self.rss_before:  # not a server scenario
            return f"{'OK  ' if self.ok else 'FAIL'} {self.name:<28} {self.note}"
        probe = self.probe.line() if self.probe is not None else "-"
        return (f"{'OK  ' if self.ok else 'FAIL'} {self.name:<28} RSS {self.rss_before:6.1f} -> "
                f"peak {self.rss_peak:6.1f} -> {self.rss_after:6.1f} MiB | well-behaved: "
                f"{probe}{' | ' + self.note if self.note else ''}")


class RssWatch:
    """Samples a process's VmRSS every 50 ms in a thread; ``peak`` is the maximum seen."""

    def __init__(self, server: sc.Server) -> None:
        self.server = server
        self.peak = server.rss_mib()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            try:
                self.peak = max(self.peak, self.server.rss_mib())
            except OSError:
                return

    def __enter__(self) -> RssWatch:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def attack(name: str, server_args: list[str], attacks: list[str], seconds: float, *,
           prober: str, drive_id: int = 2, setup: Callable[[sc.Server], object] | None = None
           ) -> Result:
    """Run ``attacks`` (soak_clients.ATTACKS names, own processes) beside a prober."""
    mode = "fast" if "--fast" in server_args else "paced"
    deadline_s = ENIP_TARGET_S if prober == "enip" else DEADLINE_S[mode]
    server = sc.start_server(*server_args)
    extra = setup(server) if setup is not None else None
    try:
        time.sleep(0.5)
        before = server.rss_mib()
        procs = [sc.attack_process(a, server.port, seconds) for a in attacks]
        probe_fn = PROBERS[prober]
        with RssWatch(server) as watch:
            time.sleep(min(1.0, seconds / 4))  # the attack is under way
            try:
                probe: sc.Latency | None = probe_fn(server.port, drive_id, seconds - 1.5,
                                                    deadline_s)
            except OSError as exc:
                probe = None
                note = f"prober failed: {exc}"
            else:
                note = ""
            for p in procs:
                p.wait(seconds + 30)
            time.sleep(1.0)
        after = server.rss_mib() if server.alive() else float("nan")
        alive = server.alive()
    finally:
        if isinstance(extra, list):
            for s in extra:
                s.close()
        _, err = server.stop()
    logged = [line for line in err.splitlines()
              if not line.startswith(("stopped", "servobus sim"))]  # banner, summary
    if "Traceback" in err:
        note += " TRACEBACK in server stderr"
        alive = False
    if logged:
        note += f" server log: {len(logged)} line(s), e.g. {logged[0][:100]!r}"
    return Result(name, before, max(watch.peak, before), after, probe, alive, note.strip())


def tap_never_reading(server: sc.Server) -> list[object]:
    """Connect to the tap (its port is on the second stdout line) and never read."""
    import socket

    assert server.proc.stdout is not None
    line = server.proc.stdout.readline().strip()
    port = int(line.rsplit(":", 1)[1])
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # before connect: small window
    sock.connect(("127.0.0.1", port))
    return [sock]


def burst_and_leave(seconds: float) -> Result:
    """64 KiB of reads from a client that leaves at once: how long until the line answers."""
    server = sc.start_server("dyn2", "--listen", "tcp://127.0.0.1:0", "--ids", "1,2")
    try:
        time.sleep(0.5)
        before = server.rss_mib()
        sc.dyn2_burst_and_leave(server.port)
        first = sc.dyn2_prober(server.port, 2, 0.01, 30.0)
        probe = sc.dyn2_prober(server.port, 2, min(seconds, 3.0), DEADLINE_S["paced"])
        note = f"first reply after the burst {first.worst_ms:.1f} ms"
        peak = server.rss_mib()
        after = server.rss_mib()
        alive = server.alive()
    finally:
        server.stop()
    return Result("dyn2 paced burst+leave", before, peak, after, probe, alive, note)


def connections(kind: str, extra: list[str], count: int, expect_refused: bool) -> Result:
    args = (["dyn2", "--listen", "tcp://127.0.0.1:0", "--fast", "--ids", "1,2"]
            if kind == "dyn2" else ["dyncan", "--socketcand", "127.0.0.1:0", "--fast",
                                    "--ids", "1,2"])
    server = sc.start_server(*args, *extra)
    name = f"{kind} {count} connections{' (cap)' if expect_refused else ''}"
    try:
        time.sleep(0.3)
        before = server.rss_mib()
        with RssWatch(server) as watch, sc.idle_connections(server.port, count) as (kept, refused):
            probe_fn = sc.dyn2_prober if kind == "dyn2" else sc.can_prober
            try:
                probe: sc.Latency | None = probe_fn(server.port, 2, 1.0, DEADLINE_S["fast"])
                note = f"held {len(kept)}, refused {refused}"
            except OSError as exc:
                probe, note = None, f"held {len(kept)}, refused {refused}, prober: {exc}"
        time.sleep(0.5)
        after = server.rss_mib() if server.alive() else float("nan")
        alive = server.alive()
    finally:
        _, err = server.stop()
    logged = [ln for ln in err.splitlines() if "refusing" in ln]
    note += f"; log lines about the cap: {len(logged)}"
    if "Traceback" in err:
        alive, note = False, note + " TRACEBACK"
    return Result(name, before, max(watch.peak, before), after, probe, alive, note)


def state_fuzz() -> Result:
    """Random corruptions of a valid --state file: each is accepted as valid or refused with
    one StateFileError line; nothing else may happen, and a refused file stays as it was."""
    import json
    import random
    import tempfile
    from pathlib import Path

    from servobus.families.dmm import params as P
    from servobus.sim.core.state_file import StateFile, StateFileError, parse_state
    from servobus.sim.dmm.eeprom import DMM_STATE

    rng = random.Random(8)
    valid = json.dumps({str(i): {"drive_id": i, "params": P.defaults(), "config": 5,
                                 "origin": 100 * i, "writes": {"main_gain": i}}
                        for i in (1, 2, 3)}, indent=1).encode()
    tokens = [b"null", b"[]", b"{}", b"-1", b"1e9", b"1.5", b"true", b'"x"', b"NaN", b"99999"]
    refused = accepted = other = 0
    with tempfile.TemporaryDirectory() as tmp:
        for n in range(STATE_MUTATIONS):
            raw = bytearray(valid)
            kind = rng.randrange(4)
            if kind == 0:
                del raw[rng.randrange(len(raw)):]
            elif kind == 1:
                for _ in range(rng.randrange(1, 4)):
                    raw[rng.randrange(len(raw))] = rng.randrange(256)
            elif kind == 2:
                at = rng.randrange(len(raw))
                raw[at:at + rng.randrange(1, 6)] = rng.choice(tokens)
            else:
                raw = bytearray(rng.randbytes(rng.randrange(64)))
            try:
                if n < STATE_FILES:
                    path = Path(tmp) / f"s{n}.json"
                    path.write_bytes(raw)
                    try:
                        StateFile(path, DMM_STATE)
                    except StateFileError:
                        if path.read_bytes() != raw:
                            other += 1  # a refused file must never be rewritten
                        raise
                else:
                    parse_state(bytes(raw), "fuzz.json", DMM_STATE)
                accepted += 1
            except StateFileError as exc:
                refused += 1
                if "\n" in str(exc):
                    other += 1
            except Exception:
                other += 1
    return Result("state file fuzz", 0.0, 0.0, 0.0, None, other == 0,
                  f"{STATE_MUTATIONS} corruptions: {refused} refused (one line each), "
                  f"{accepted} still valid, {other} anything else")


def scenarios(seconds: float) -> dict[str, Callable[[], Result]]:
    dyn2 = ["dyn2", "--listen", "tcp://127.0.0.1:0", "--ids", "1,2"]
    can = ["dyncan", "--socketcand", "127.0.0.1:0", "--ids", "1,2"]
    fast = ["--fast"]
    tap = ["--tap", "tcp://127.0.0.1:0"]
    enip = ["enip", "--tcp-port", "0", "--udp-port", "0"]
    s = seconds
    return {
        "dyn2 paced flood": lambda: attack("dyn2 paced flood", dyn2, ["dyn2-flood"], s,
                                           prober="dyn2"),
        "dyn2 fast greedy": lambda: attack("dyn2 fast greedy", dyn2 + fast,
                                           ["dyn2-flood", "dyn2-flood"], s, prober="dyn2"),
        "dyn2 fast never-reading": lambda: attack("dyn2 fast never-reading", dyn2 + fast,
                                                  ["dyn2-flood-noread"], s, prober="dyn2"),
        "dyn2 paced never-reading": lambda: attack("dyn2 paced never-reading", dyn2,
                                                   ["dyn2-flood-noread"], s, prober="dyn2"),
        "dyn2 fast tap never-reading": lambda: attack(
            "dyn2 fast tap never-reading", dyn2 + fast + tap, ["dyn2-flood"], s,
            prober="dyn2", setup=tap_never_reading),
        "dyn2 fast garbage": lambda: attack("dyn2 fast garbage", dyn2 + fast,
                                            ["garbage", "garbage"], s, prober="dyn2"),
        "dyn2 paced garbage": lambda: attack("dyn2 paced garbage", dyn2, ["garbage"], s,
                                             prober="dyn2"),
        "dyn2 paced burst+leave": lambda: burst_and_leave(s),
        "dyn2 connections": lambda: connections("dyn2", ["--max-clients", "4096"],
                                                CONNECTIONS, False),
        "dyn2 connections cap": lambda: connections("dyn2", [], CONNECTIONS, True),
        "can paced flood": lambda: attack("can paced flood", can, ["can-flood"], s,
                                          prober="can"),
        "can fast greedy": lambda: attack("can fast greedy", can + fast, ["can-flood"], s,
                                          prober="can"),
        "can fast never-reading": lambda: attack("can fast never-reading", can + fast,
                                                 ["can-flood-noread"], s, prober="can"),
        "can paced never-reading": lambda: attack("can paced never-reading", can,
                                                  ["can-flood-noread"], s, prober="can"),
        "can fast garbage": lambda: attack("can fast garbage", can + fast, ["can-garbage"], s,
                                           prober="can"),
        "can connections": lambda: connections("can", ["--max-clients", "4096"],
                                               CONNECTIONS, False),
        "can connections cap": lambda: connections("can", [], CONNECTIONS, True),
        "enip never-reading": lambda: attack("enip never-reading", enip,
                                             ["enip-flood-noread", "enip-flood-noread"], s,
                                             prober="enip"),
        "enip greedy": lambda: attack("enip greedy", enip, ["enip-flood", "enip-flood"], s,
                                      prober="enip"),
        "state file fuzz": state_fuzz,
    }


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.soak")
    parser.add_argument("select", nargs="*", help="run scenarios whose name contains one")
    parser.add_argument("--seconds", type=float, default=8.0, help="length of each attack")
    args = parser.parse_args(argv)
    todo = scenarios(args.seconds)
    names = [n for n in todo if not args.select or any(a in n for a in args.select)]
    failed = 0
    for name in names:
        try:
            result = todo[name]()
        except Exception as exc:  # a scenario that cannot run is a failure, not a crash
            print(f"FAIL {name:<28} {type(exc).__name__}: {exc}", flush=True)
            failed += 1
            continue
        print(result.line(), flush=True)
        failed += not result.ok
    print(f"{len(names) - failed}/{len(names)} scenario(s) OK")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
