"""A minimal EtherNet/IP originator written from the CIP specification with struct only.

Independent of servobus's codec on purpose: it checks the virtual DYN5 against the wire
format as the CIP spec writes it (encapsulation header, CPF, Forward_Open, Class 1 frames),
not against servobus's own reading of it.
"""

from __future__ import annotations

import socket
import struct
import time
from dataclasses import dataclass

HEADER = struct.Struct("<HHII8sI")
SEND_RR_DATA = 0x6F
REGISTER_SESSION = 0x65
UNREGISTER_SESSION = 0x66
CM_PATH = bytes((0x20, 0x06, 0x24, 0x01))
P2P_SCHEDULED = 0x4000 | 0x0800  # point-to-point (bits 14-13 = 2), scheduled priority
DYN5_PATH = bytes((0x20, 0x04, 0x24, 0x00, 0x2C, 0x65, 0x2C, 0x64))  # config 0, 101, 100


def packet(command: int, data: bytes = b"", session: int = 0, context: bytes = b"rawtest!",
           status: int = 0, options: int = 0) -> bytes:
    return HEADER.pack(command, len(data), session, status, context, options) + data


def recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("closed")
        buf += chunk
    return buf


def recv_packet(sock: socket.socket) -> tuple[tuple[int, int, int, int, bytes, int], bytes]:
    head = HEADER.unpack(recv_exact(sock, 24))
    return head, recv_exact(sock, head[1])


def sockaddr_item(item_type: int, ip: str, port: int) -> bytes:
    body = struct.pack(">hH4s8s", 2, port, socket.inet_aton(ip), bytes(8))
    return struct.pack("<HH", item_type, 16) + body


def rr_data(mr: bytes, extra_items: tuple[bytes, ...] = ()) -> bytes:
    items = struct.pack("<HH", 0, 0) + struct.pack("<HH", 0xB2, len(mr)) + mr
    return struct.pack("<IHH", 0, 5, 2 + len(extra_items)) + items + b"".join(extra_items)


def parse_rr_reply(data: bytes) -> tuple[bytes, list[tuple[int, bytes]]]:
    """(Message Router response, all CPF items) of a SendRRData reply."""
    (count,) = struct.unpack_from("<H", data, 6)
    pos, items = 8, []
    for _ in range(count):
        t, n = struct.unpack_from("<HH", data, pos)
        items.append((t, data[pos + 4:pos + 4 + n]))
        pos += 4 + n
    mr = next(d for t, d in items if t == 0xB2)
    return mr, items


def forward_open_data(*, serial: int = 0x1234, vendor: int = 0x4242, orig_serial: int = 0xCAFE,
                      t_o_id: int = 0x7000_0001, rpi_us: int = 10_000, multiplier: int = 0,
                      o_t_size: int = 10, t_o_size: int = 18, path: bytes = DYN5_PATH,
                      transport: int = 0x01, o_t_type: int = P2P_SCHEDULED,
                      t_o_type: int = P2P_SCHEDULED) -> bytes:
    """Forward_Open service data (CIP Vol. 1 3-5.4.1)."""
    return struct.pack("<BBIIHHIB3xIHIHB", 0x0A, 0x0E, 0, t_o_id, serial, vendor, orig_serial,
                       multiplier, rpi_us, o_t_type | o_t_size, rpi_us, t_o_type | t_o_size,
                       transport) + bytes((len(path) // 2,)) + path


def forward_close_data(*, serial: int = 0x1234, vendor: int = 0x4242, orig_serial: int = 0xCAFE,
                       path: bytes = DYN5_PATH) -> bytes:
    return struct.pack("<BBHHI", 0x0A, 0x0E, serial, vendor, orig_serial) + bytes(
        (len(path) // 2, 0)) + path


def mr_request(service: int, path: bytes, data: bytes = b"") -> bytes:
    return bytes((service, len(path) // 2)) + path + data


@dataclass
class MrReply:
    service: int
    status: int
    extra: tuple[int, ...]
    data: bytes


def parse_mr(raw: bytes) -> MrReply:
    n = raw[3]
    extra = struct.unpack_from(f"<{n}H", raw, 4)
    return MrReply(raw[0], raw[2], extra, raw[4 + 2 * n:])


class RawClient:
    """One TCP session."""

    def __init__(self, host: str, port: int, *, register: bool = True) -> None:
        self.sock = socket.create_connection((host, port), timeout=5.0)
        self.session = 0
        if register:
            self.sock.sendall(packet(REGISTER_SESSION, struct.pack("<HH", 1, 0)))
            head, _ = recv_packet(self.sock)
            assert head[3] == 0, head
            self.session = head[2]

    def exchange(self, command: int, data: bytes = b"", **kw: object
                 ) -> tuple[tuple[int, int, int, int, bytes, int], bytes]:
        kw.setdefault("session", self.session)
        self.sock.sendall(packet(command, data, **kw))  # type: ignore[arg-type]
        return recv_packet(self.sock)

    def request(self, mr: bytes, extra_items: tuple[bytes, ...] = ()
                ) -> tuple[MrReply, list[tuple[int, bytes]]]:
        head, data = self.exchange(SEND_RR_DATA, rr_data(mr, extra_items))
        assert head[3] == 0, f"encapsulation status 0x{head[3]:04X}"
        raw, items = parse_rr_reply(data)
        return parse_mr(raw), items

    def close(self) -> None:
        self.sock.close()


@dataclass
class InFrame:
    connection_id: int
    sequence: int
    count: int
    values: tuple[int, int, int, int]
    arrival: float


def parse_io(datagram: bytes, arrival: float) -> InFrame:
    count, = struct.unpack_from("<H", datagram)
    assert count == 2
    t1, n1, cid, seq = struct.unpack_from("<HHII", datagram, 2)
    assert (t1, n1) == (0x8002, 8)
    t2, n2 = struct.unpack_from("<HH", datagram, 14)
    assert (t2, n2) == (0x00B1, 18)
    cip_count, *values = struct.unpack_from("<HiiiI", datagram, 18)
    return InFrame(cid, seq, cip_count, tuple(values), arrival)  # type: ignore[arg-type]


def output_datagram(o_t_id: int, sequence: int, count: int, word: int, run: bool = True) -> bytes:
    data = struct.pack("<HII", count, 1 if run else 0, word)
    return (struct.pack("<H", 2) + struct.pack("<HHII", 0x8002, 8, o_t_id, sequence)
            + struct.pack("<HH", 0xB1, len(data)) + data)


class IoSocket:
    """The originator's UDP socket for Class 1 (receives T->O, sends O->T)."""

    def __init__(self, host: str = "127.0.0.1") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.port = self.sock.getsockname()[1]

    def receive(self, timeout: float = 2.0) -> InFrame:
        self.sock.settimeout(timeout)
        data = self.sock.recv(2048)
        return parse_io(data, time.monotonic())

    def close(self) -> None:
        self.sock.close()
