"""Attack and probe clients for the soak run (``python -m benchmarks.soak``), raw sockets only.

Each attack also runs as its own process (``python -m benchmarks.soak_clients NAME PORT
SECONDS``) so a flooding client does not share an interpreter (and its GIL) with the
well-behaved client whose latency is measured.
"""

from __future__ import annotations

import contextlib
import random
import re
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyncan import codec as cc

H = c.HostFunction
STATUS_REPLY_LEN = 4  # Is_Status: start byte, function, 1 data byte, checksum


# ---------------------------------------------------------------- server processes
@dataclass
class Server:
    proc: subprocess.Popen[str]
    port: int

    @property
    def pid(self) -> int:
        return self.proc.pid

    def rss_mib(self) -> float:
        return rss_mib(self.proc.pid)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> tuple[int, str]:
        """SIGTERM, wait; return (exit code, stderr)."""
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            _, err = self.proc.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return self.proc.returncode, err


def start_server(*args: str) -> Server:
    """``servobus sim ...`` as a subprocess; waits for its ``listening on`` line."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "sim", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], 20)
    line = proc.stdout.readline().strip() if ready else ""
    if not line.startswith("listening on "):
        proc.kill()
        _, err = proc.communicate()
        raise RuntimeError(f"server did not start: {line!r} {err[-500:]!r}")
    found = re.search(r":(\d+)", line.removeprefix("listening on "))
    assert found is not None, line
    return Server(proc, int(found.group(1)))


def rss_mib(pid: int) -> float:
    """Resident set size of a process (Linux /proc), MiB."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


def attack_process(name: str, port: int, seconds: float) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "benchmarks.soak_clients", name,
                             str(port), str(seconds)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


# ---------------------------------------------------------------- DYN232M (sim dyn232)
def dyn2_status(drive_id: int) -> bytes:
    return c.encode(drive_id, DmmFunction.READ_DRIVE_STATUS)


@dataclass
class Latency:
    samples: list[float] = field(default_factory=list)
    misses: int = 0

    @property
    def worst_ms(self) -> float:
        return max(self.samples, default=float("nan")) * 1000

    def line(self) -> str:
        n = len(self.samples)
        med = sorted(self.samples)[n // 2] * 1000 if n else float("nan")
        return (f"{n} replies, {self.misses} missed, median {med:.1f} ms, "
                f"worst {self.worst_ms:.1f} ms")


def dyn2_prober(port: int, drive_id: int, seconds: float, deadline_s: float,
                period_s: float = 0.02) -> Latency:
    """A well-behaved host: one status read at a time, ``deadline_s`` per reply."""
    out = Latency()
    request = dyn2_status(drive_id)
    end = time.monotonic() + seconds
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        while time.monotonic() < end:
            t0 = time.monotonic()
            sock.sendall(request)
            got = b""
            while len(got) < STATUS_REPLY_LEN:
                left = t0 + deadline_s - time.monotonic()
                if left <= 0 or not readable(sock, left):
                    break
                chunk = sock.recv(64)
                if not chunk:
                    raise ConnectionError("server closed the prober's connection")
                got += chunk
            if len(got) >= STATUS_REPLY_LEN:
                out.samples.append(time.monotonic() - t0)
            else:
                out.misses += 1
                _drain(sock, 0.3)  # a late reply must not be taken for the next one
            time.sleep(period_s)
    return out


def readable(sock: socket.socket, timeout: float) -> bool:
    """``select`` for one socket without its FD_SETSIZE (1024) limit."""
    poller = select.poll()
    poller.register(sock.fileno(), select.POLLIN)
    return bool(poller.poll(max(0.0, timeout) * 1000))


def _drain(sock: socket.socket, quiet_s: float) -> None:
    while readable(sock, quiet_s):
        if not sock.recv(65536):
            return


def dyn2_flood(port: int, seconds: float, *, read: bool = True, drive_id: int = 1) -> int:
    """Send status reads as fast as TCP takes them; drain replies in a thread if ``read``."""
    burst = dyn2_status(drive_id) * 4096
    end = time.monotonic() + seconds
    sent = 0
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.settimeout(0.2)
        stop = threading.Event()
        reader = threading.Thread(target=_reader, args=(sock, stop), daemon=True)
        if read:
            reader.start()
        while time.monotonic() < end:
            try:
                sent += sock.send(burst)
            except TimeoutError:
                continue
            except OSError:
                break
        stop.set()
        if read:
            reader.join(2)
    return sent


def _reader(sock: socket.socket, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            if not sock.recv(1 << 16):
                return
        except TimeoutError:
            continue
        except OSError:
            return


def dyn2_burst_and_leave(port: int, size: int = 64 * 1024) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall((dyn2_status(1) * (size // 4 + 1))[:size])


def garbage(port: int, seconds: float, seed: int = 1) -> int:
    """Random bytes (every value) as fast as TCP takes them; replies drained."""
    rng = random.Random(seed)
    blob = rng.randbytes(1 << 16)
    return _send_for(socket.create_connection(("127.0.0.1", port), timeout=5), seconds,
                     lambda: blob)


def _send_for(sock: socket.socket, seconds: float, payload: Callable[[], bytes]) -> int:
    """Send ``payload()`` until ``seconds`` pass, draining replies; closes ``sock``."""
    end = time.monotonic() + seconds
    sent = 0
    with sock:
        sock.settimeout(0.2)
        stop = threading.Event()
        reader = threading.Thread(target=_reader, args=(sock, stop), daemon=True)
        reader.start()
        while time.monotonic() < end:
            try:
                sent += sock.send(payload())
            except TimeoutError:
                continue
            except OSError:
                break
        stop.set()
        reader.join(2)
    return sent


@contextlib.contextmanager
def idle_connections(port: int, count: int, settle_s: float = 1.0
                     ) -> Iterator[tuple[list[socket.socket], int]]:
    """Open ``count`` connections; yield (the ones the server kept, how many it refused).

    A refused connection is one the server closed at once (EOF or reset within
    ``settle_s``).
    """
    socks: list[socket.socket] = []
    try:
        for _ in range(count):
            s = socket.socket()
            s.settimeout(5)
            s.connect(("127.0.0.1", port))
            s.setblocking(False)
            socks.append(s)
        end = time.monotonic() + settle_s
        refused: set[socket.socket] = set()
        while time.monotonic() < end:
            readable, _, _ = select_many(socks, max(0.0, end - time.monotonic()))
            for s in readable:
                with contextlib.suppress(BlockingIOError):
                    try:
                        data = s.recv(4096)
                    except ConnectionResetError:
                        data = b""
                    if not data:
                        refused.add(s)
            if not readable:
                break
        kept = [s for s in socks if s not in refused]
        yield kept, len(refused)
    finally:
        for s in socks:
            s.close()


def select_many(socks: list[socket.socket], timeout: float
                ) -> tuple[list[socket.socket], list[socket.socket], list[socket.socket]]:
    """``select`` for any number of sockets (poll underneath: no FD_SETSIZE limit)."""
    poller = select.poll()
    by_fd = {s.fileno(): s for s in socks}
    for fd in by_fd:
        poller.register(fd, select.POLLIN)
    events = poller.poll(timeout * 1000)
    return [by_fd[fd] for fd, _ in events], [], []


# ---------------------------------------------------------------- socketcand (sim dyncan)
def can_send_text(drive_id: int, function: cc.Function = DmmFunction.READ_DRIVE_STATUS) -> str:
    ident, data = cc.encode(cc.request(drive_id, function))
    return f"< send {ident:03X} {len(data):X} {' '.join(f'{b:02X}' for b in data)} >".replace(
        "  ", " ")


def can_session(port: int, timeout: float = 5.0) -> socket.socket:
    """Connect, ``< open can0 >``, ``< rawmode >``; return the socket in rawmode."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    expect(sock, b"< hi >")
    sock.sendall(b"< open can0 >")
    expect(sock, b"< ok >")
    sock.sendall(b"< rawmode >")
    expect(sock, b"< ok >")
    time.sleep(0.05)  # the hub starts sending frames 20 ms after rawmode's ok
    return sock


def expect(sock: socket.socket, text: bytes, timeout: float = 5.0) -> bytes:
    """Read until ``text`` has arrived; return everything read."""
    got = b""
    end = time.monotonic() + timeout
    while text not in got:
        left = end - time.monotonic()
        if left <= 0 or not readable(sock, left):
            raise TimeoutError(f"expected {text!r}, got {got[-200:]!r}")
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError(f"closed while expecting {text!r}, got {got[-200:]!r}")
        got += chunk
    return got


def can_prober(port: int, drive_id: int, seconds: float, deadline_s: float,
               period_s: float = 0.02) -> Latency:
    """One status read at a time on ``drive_id``; other frames on the bus are skipped."""
    out = Latency()
    request = can_send_text(drive_id).encode()
    ident, _ = cc.encode(cc.request(drive_id, DmmFunction.READ_DRIVE_STATUS))
    marker = f"< frame {ident:03X} ".encode()
    end = time.monotonic() + seconds
    sock = can_session(port)
    try:
        while time.monotonic() < end:
            _drain(sock, 0.0)
            t0 = time.monotonic()
            sock.sendall(request)
            try:
                expect_frame(sock, marker, t0 + deadline_s)
                out.samples.append(time.monotonic() - t0)
            except TimeoutError:
                out.misses += 1
            time.sleep(period_s)
    finally:
        sock.close()
    return out


def expect_frame(sock: socket.socket, marker: bytes, deadline: float) -> None:
    tail = b""
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not readable(sock, left):
            raise TimeoutError("no reply")
        chunk = sock.recv(1 << 16)
        if not chunk:
            raise ConnectionError("server closed the prober's session")
        tail = tail[-64:] + chunk
        if marker in tail:
            return


def can_flood(port: int, seconds: float, *, read: bool = True, drive_id: int = 1) -> int:
    burst = (can_send_text(drive_id) * 512).encode()
    end = time.monotonic() + seconds
    sent = 0
    sock = can_session(port)
    try:
        sock.settimeout(0.2)
        stop = threading.Event()
        reader = threading.Thread(target=_reader, args=(sock, stop), daemon=True)
        if read:
            reader.start()
        while time.monotonic() < end:
            try:
                sent += sock.send(burst)
            except TimeoutError:
                continue
            except OSError:
                break
        stop.set()
        if read:
            reader.join(2)
    finally:
        sock.close()
    return sent


def can_garbage(port: int, seconds: float, seed: int = 2) -> int:
    """Random bytes framed as socketcand messages (non-ASCII, bad numbers), replies drained."""
    rng = random.Random(seed)

    def payload() -> bytes:
        parts = []
        for _ in range(256):
            body = rng.randbytes(rng.randrange(0, 24)).replace(b"<", b"").replace(b">", b"")
            parts.append(b"< send " + body + b" >" if rng.random() < 0.7 else body)
        return b"".join(parts)

    return _send_for(can_session(port), seconds, payload)


ATTACKS: dict[str, Callable[[int, float], int]] = {
    "dyn2-flood": lambda port, s: dyn2_flood(port, s, read=True),
    "dyn2-flood-noread": lambda port, s: dyn2_flood(port, s, read=False),
    "garbage": garbage,
    "can-flood": lambda port, s: can_flood(port, s, read=True),
    "can-flood-noread": lambda port, s: can_flood(port, s, read=False),
    "can-garbage": can_garbage,
    "enip-flood": lambda port, s: enip_flood(port, s, read=True),
    "enip-flood-noread": lambda port, s: enip_flood(port, s, read=False),
}


# ---------------------------------------------------------------- EtherNet/IP (sim enip)
ENCAP = struct.Struct("<HHII8sI")  # command, length, session, status, context, options
REGISTER_SESSION, SEND_RR_DATA = 0x65, 0x6F
PARAM_1 = bytes((0x0E, 3, 0x20, 0x0F, 0x24, 1, 0x30, 0x01))  # Get_Attribute_Single param 1


def enip_read(session: int, context: bytes = b"soaktest") -> bytes:
    """SendRRData: an unconnected Get_Attribute_Single of parameter 1 (CIP Vol. 2 ch. 2)."""
    cpf = (struct.pack("<IHH", 0, 5, 2) + struct.pack("<HH", 0, 0)
           + struct.pack("<HH", 0xB2, len(PARAM_1)) + PARAM_1)
    return ENCAP.pack(SEND_RR_DATA, len(cpf), session, 0, context, 0) + cpf


def _recv_exact(sock: socket.socket, n: int, deadline: float) -> bytes | None:
    got = b""
    while len(got) < n:
        left = deadline - time.monotonic()
        if left <= 0 or not readable(sock, left):
            return None
        chunk = sock.recv(n - len(got))
        if not chunk:
            raise ConnectionError("server closed the connection")
        got += chunk
    return got


def enip_session(port: int) -> tuple[socket.socket, int]:
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.sendall(ENCAP.pack(REGISTER_SESSION, 4, 0, 0, b"register", 0) + struct.pack("<HH", 1, 0))
    head = _recv_exact(sock, ENCAP.size + 4, time.monotonic() + 5)
    if head is None:
        raise ConnectionError("no RegisterSession reply")
    return sock, ENCAP.unpack_from(head)[2]


def enip_prober(port: int, drive_id: int, seconds: float, deadline_s: float,
                period_s: float = 0.02) -> Latency:
    """A polite originator: one parameter read at a time, ``deadline_s`` per reply."""
    out = Latency()
    sock, session = enip_session(port)
    end = time.monotonic() + seconds
    with sock:
        while time.monotonic() < end:
            t0 = time.monotonic()
            sock.sendall(enip_read(session))
            head = _recv_exact(sock, ENCAP.size, t0 + deadline_s)
            body = (_recv_exact(sock, ENCAP.unpack(head)[1], t0 + deadline_s)
                    if head is not None else None)
            if body is not None:
                out.samples.append(time.monotonic() - t0)
            else:
                out.misses += 1
                _drain(sock, 0.3)  # a late reply must not be taken for the next one
            time.sleep(period_s)
    return out


def enip_flood(port: int, seconds: float, *, read: bool = True) -> int:
    """Valid parameter reads as fast as TCP takes them; replies drained only if ``read``."""
    sock, session = enip_session(port)
    burst = enip_read(session, b"flooder!") * 1024
    if read:
        return _send_for(sock, seconds, lambda: burst)
    end = time.monotonic() + seconds
    sent = 0
    with sock:
        sock.settimeout(0.2)
        while time.monotonic() < end:
            try:
                sent += sock.send(burst)
            except TimeoutError:
                continue
            except OSError:
                break
    return sent


def main(argv: list[str]) -> int:
    name, port, seconds = argv[0], int(argv[1]), float(argv[2])
    ATTACKS[name](port, seconds)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
