"""Shared pieces of the simulator abuse tests: server subprocesses, memory, probes, floods.

Everything is loopback and bounded in time: every server runs with ``--duration``, every
client loop has an end time, every wait a deadline.
"""

from __future__ import annotations

import contextlib
import os
import resource
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest
from subprocess_rig import read_line, stop_process

from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyncan import codec as cc

SERVOBUS = [sys.executable, "-m", "servobus"]
ANSWER_S = 5.0  # every read of the well-behaved client is answered within this
GOOD_S = 0.5  # ... and most of them within this
STATUS_REPLY_LEN = 4  # DYN232M Is_Status: start byte, function, one data byte, checksum


class Sim:
    """``servobus sim ...`` in a subprocess, bounded by ``--duration``."""

    def __init__(self, *args: str, duration: float = 300.0) -> None:
        self.proc = subprocess.Popen([*SERVOBUS, "sim", *args, "--duration", str(duration)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.stderr = ""

    def line(self, timeout: float = 20.0) -> str:
        """The next stdout line."""
        return read_line(self.proc, timeout=timeout)

    def port(self) -> int:
        text = self.line()
        assert text.startswith("listening on "), text
        return int(text.rsplit(":", 1)[1])

    def rss_mib(self) -> float:
        with open(f"/proc/{self.proc.pid}/status") as f:
            for row in f:
                if row.startswith("VmRSS:"):
                    return int(row.split()[1]) / 1024
        raise AssertionError("no VmRSS")

    def connections(self) -> int:
        """The server's open sockets (listeners included), from /proc/<pid>/fd."""
        count = 0
        for fd in os.listdir(f"/proc/{self.proc.pid}/fd"):
            with contextlib.suppress(OSError):
                count += os.readlink(f"/proc/{self.proc.pid}/fd/{fd}").startswith("socket:")
        return count

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stderr_so_far(self) -> str:
        """What the server wrote to stderr until now (reads the pipe without blocking)."""
        assert self.proc.stderr is not None
        fd = self.proc.stderr.fileno()
        os.set_blocking(fd, False)
        try:
            self.stderr += os.read(fd, 1 << 16).decode(errors="replace")
        except BlockingIOError:
            pass
        finally:
            os.set_blocking(fd, True)
        return self.stderr

    def stop(self) -> int:
        """SIGTERM and wait; keeps stderr in ``self.stderr``; returns the exit code."""
        self.stderr += stop_process(self.proc)
        return self.proc.returncode


@contextlib.contextmanager
def sim(*args: str, duration: float = 300.0) -> Iterator[Sim]:
    """A server for the ``with`` block; ``duration`` is only a safety net (a loaded machine
    may take minutes over a test; the block's end stops the server)."""
    p = Sim(*args, duration=duration)
    try:
        yield p
    finally:
        p.stop()


def run_cli(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SERVOBUS, *args], capture_output=True, text=True, timeout=timeout)


def readable(sock: socket.socket, timeout: float) -> bool:
    """Wait for input on one socket (poll: no FD_SETSIZE limit on descriptor numbers)."""
    poller = select.poll()
    poller.register(sock.fileno(), select.POLLIN)
    return bool(poller.poll(max(0.0, timeout) * 1000))


def need_descriptors(count: int) -> None:
    """Raise this process's soft RLIMIT_NOFILE to ``count`` or skip the test."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < count:
        if hard != resource.RLIM_INFINITY and hard < count:
            pytest.skip(f"needs {count} open files; the hard limit is {hard}")
        resource.setrlimit(resource.RLIMIT_NOFILE, (count, hard))


def assert_served(times: list[float]) -> None:
    """The well-behaved client is served beside the abuse: every read answered (within
    ANSWER_S) and three quarters of them within GOOD_S.

    Before the fixes its reads took 1.7 s, never came back, or 8 of 9 missed 250 ms: all
    caught. Required of every read, GOOD_S failed beside two CPU hogs (one read in 60 missed
    it): a loaded machine delays single reads, which is not starvation.
    """
    assert max(times) < ANSWER_S, sorted(times)[-5:]
    assert sum(t < GOOD_S for t in times) >= 0.75 * len(times), sorted(times)


# ---------------------------------------------------------------- DYN232M
def dyn2_status(drive_id: int) -> bytes:
    return c.encode(drive_id, DmmFunction.READ_DRIVE_STATUS)


def dyn2_latencies(port: int, drive_id: int, count: int, deadline_s: float,
                   period_s: float = 0.02) -> list[float]:
    """``count`` status reads, one at a time; the round-trip times (inf for a miss)."""
    out = []
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for _ in range(count):
            t0 = time.monotonic()
            sock.sendall(dyn2_status(drive_id))
            got = b""
            while len(got) < STATUS_REPLY_LEN and readable(
                    sock, t0 + deadline_s - time.monotonic()):
                chunk = sock.recv(64)
                assert chunk, "the server closed the well-behaved client"
                got += chunk
            out.append(time.monotonic() - t0 if len(got) >= STATUS_REPLY_LEN else float("inf"))
            time.sleep(period_s)  # a well-behaved client's pace between reads
    return out


class Flood:
    """A thread sending ``payload`` over and over to a fresh connection until stopped;
    replies are read and thrown away unless ``read=False``."""

    def __init__(self, port: int, payload: bytes, *, read: bool = True,
                 handshake: bool = False) -> None:
        self.sock = (can_session(port) if handshake
                     else socket.create_connection(("127.0.0.1", port), timeout=5))
        self.sock.settimeout(0.2)
        self.payload = payload
        self.sent = 0
        self.stop = threading.Event()
        self._threads = [threading.Thread(target=self._send, daemon=True)]
        if read:
            self._threads.append(threading.Thread(target=self._recv, daemon=True))

    def __enter__(self) -> Flood:
        for t in self._threads:
            t.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        for t in self._threads:
            t.join(5)
        self.sock.close()

    def _send(self) -> None:
        while not self.stop.is_set():
            try:
                self.sent += self.sock.send(self.payload)
            except TimeoutError:
                continue
            except OSError:
                return

    def _recv(self) -> None:
        while not self.stop.is_set():
            try:
                if not self.sock.recv(1 << 16):
                    return
            except TimeoutError:
                continue
            except OSError:
                return


# ---------------------------------------------------------------- socketcand
def can_send(drive_id: int, function: cc.Function = DmmFunction.READ_DRIVE_STATUS) -> bytes:
    ident, data = cc.encode(cc.request(drive_id, function))
    fields = [f"{ident:03X}", f"{len(data):X}", *(f"{b:02X}" for b in data)]
    return f"< send {' '.join(fields)} >".encode()


def can_session(port: int) -> socket.socket:
    """A socketcand session in rawmode (after the hub's settle time)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    expect(sock, b"< hi >")
    sock.sendall(b"< open can0 >")
    expect(sock, b"< ok >")
    sock.sendall(b"< rawmode >")
    expect(sock, b"< ok >")
    # The hub sends bus frames to a client only after its settle time; it handles commands in
    # order, so the answer to an echo sent now comes once that settle is over.
    sock.sendall(b"< echo >")
    expect(sock, b"< echo >")
    return sock


def expect(sock: socket.socket, text: bytes, timeout: float = 5.0) -> bytes:
    """Read until ``text`` arrived; return the bytes read (at most the last 64 KiB).

    Raises TimeoutError or ConnectionError (closed first), naming what was read.
    """
    got = b""
    end = time.monotonic() + timeout
    while True:
        if not readable(sock, end - time.monotonic()):
            raise TimeoutError(f"expected {text!r}, got {got[-300:]!r}")
        chunk = sock.recv(1 << 16)
        if not chunk:
            raise ConnectionError(f"closed while expecting {text!r}, got {got[-300:]!r}")
        window = got[-len(text):] + chunk
        got = (got + chunk)[-(1 << 16):]
        if text in window:
            return got


def drain(sock: socket.socket) -> None:
    while readable(sock, 0):
        if not sock.recv(1 << 16):
            return


def can_latencies(port: int, drive_id: int, count: int, deadline_s: float,
                  period_s: float = 0.02) -> list[float]:
    """``count`` status reads on ``drive_id``, other bus traffic skipped; inf = a miss."""
    ident, _ = cc.encode(cc.request(drive_id, DmmFunction.READ_DRIVE_STATUS))
    marker = f"< frame {ident:03X} ".encode()
    out = []
    sock = can_session(port)
    try:
        for _ in range(count):
            drain(sock)
            t0 = time.monotonic()
            sock.sendall(can_send(drive_id))
            try:
                expect(sock, marker, deadline_s)
                out.append(time.monotonic() - t0)
            except TimeoutError:
                out.append(float("inf"))
            time.sleep(period_s)  # a well-behaved client's pace between reads
    finally:
        sock.close()
    return out
