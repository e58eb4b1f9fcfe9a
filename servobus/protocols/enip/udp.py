"""The scanner's UDP socket: datagrams with their arrival time, kernel-stamped where possible.

Class 1 input frames are data samples; when they arrived matters. On Linux the socket asks
the kernel for a receive timestamp (``SO_TIMESTAMPNS``; CLOCK_REALTIME, nanoseconds) and is
read with ``recvmsg`` from the event loop's reader callback, so a frame's ``wire_time`` is
when the network delivered it, not when a busy or descheduled Python process got to it. It
is converted to the ``time.monotonic()`` base with the realtime-to-monotonic offset read at
reception (differences between frames are exact to the microsecond; an NTP step of the wall
clock between two frames would show). Elsewhere (or on an event loop without ``add_reader``,
such as Windows' proactor) an asyncio datagram endpoint is used and ``wire_time`` is the
arrival time in Python, like ``time``.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import sys
import time
from collections.abc import Callable

#: Linux: SO_TIMESTAMPNS (= SCM_TIMESTAMPNS) on the common architectures (x86, arm, riscv).
SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@ll")
RECV_SIZE = 2048
ANCILLARY_SIZE = 64

#: ``on_datagram(data, (ip, port), time, wire_time)``; both times in the monotonic base.
OnDatagram = Callable[[bytes, tuple[str, int], float, float], None]


class _Endpoint(asyncio.DatagramProtocol):
    def __init__(self, on_datagram: OnDatagram) -> None:
        self.on_datagram = on_datagram

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        now = time.monotonic()
        self.on_datagram(data, addr, now, now)


class UdpSocket:
    """A bound UDP socket on the running loop (module docstring)."""

    def __init__(self, sock: socket.socket, loop: asyncio.AbstractEventLoop,
                 on_datagram: OnDatagram) -> None:
        self.sock = sock
        self.on_datagram = on_datagram
        self.kernel_time = False
        self._loop = loop
        self._transport: asyncio.DatagramTransport | None = None
        self._reading = False

    @classmethod
    async def open(cls, local: tuple[str, int], on_datagram: OnDatagram) -> UdpSocket:
        loop = asyncio.get_running_loop()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setblocking(False)
            sock.bind(local)
            udp = cls(sock, loop, on_datagram)
            if sys.platform.startswith("linux"):
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
                    udp.kernel_time = True
            try:
                loop.add_reader(sock.fileno(), udp._readable)
                udp._reading = True
            except NotImplementedError:
                udp.kernel_time = False
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _Endpoint(on_datagram), sock=sock)
                udp._transport = transport
        except BaseException:
            sock.close()
            raise
        return udp

    @property
    def sockname(self) -> tuple[str, int]:
        name = self.sock.getsockname()
        return str(name[0]), int(name[1])

    @property
    def threadsafe_send(self) -> bool:
        """:meth:`sendto` may be called from another thread (the plain socket; not the
        asyncio transport of the fallback path, e.g. Windows' proactor loop)."""
        return self._transport is None

    def sendto(self, data: bytes | bytearray, addr: tuple[str, int]) -> None:
        """Send now or drop (cyclic data: the next period carries fresh data anyway)."""
        if self._transport is not None:
            self._transport.sendto(data, addr)
            return
        with contextlib.suppress(OSError):
            self.sock.sendto(data, addr)

    def _readable(self) -> None:
        sock = self.sock
        while True:
            try:
                data, ancillary, _, addr = sock.recvmsg(RECV_SIZE, ANCILLARY_SIZE)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            now = time.monotonic()
            wire = now
            for level, kind, payload in ancillary:
                if (level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS
                        and len(payload) >= _TIMESPEC.size):
                    sec, nsec = _TIMESPEC.unpack_from(payload)
                    wire = sec + nsec * 1e-9 - (time.time() - now)
            self.on_datagram(data, addr, now, wire)

    def close(self) -> None:
        if self._reading:
            self._reading = False
            self._loop.remove_reader(self.sock.fileno())
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        else:
            self.sock.close()
