"""38400 8N1 wire-time model of one DYN232M line, and the async runner that applies it.

Model (both directions, full duplex as the manual's 7.1 table says):

* Host -> drives: a chunk handed over at monotonic time ``t`` starts on the wire at
  ``max(t, wire free)``; byte ``i`` has fully arrived ``(i + 1) x 260.4 us`` later. Each packet
  is executed at the instant its last byte arrived, in the drives' simulated time.
* Drives -> host: a reply starts when its packet was executed (or when the previous reply has
  left) and is handed to the host once its last byte has left: never faster than 260.4 us/byte.

Implementation (the wire clock and the release queue are the protocol-free
:mod:`servobus.sim.wire`, shared with the Modbus RTU line): times are computed against a
monotonic wire clock, never by sleeping per byte. A packet is executed as soon as it is
framed, with the drives advanced to its wire arrival time (which may lie up to the queued
wire time ahead of the wall clock). Nobody can observe the difference: the only way to see
the drives is a reply, and replies are released only when their wire time has come. So the
runner waits once per reply, with a precise wait: an asyncio sleep for all but the last
``coarse_s`` (event loops using epoll wake only to the millisecond), a blocking
``time.sleep`` for most of the rest, then a short spin (``spin_s``)
for the final microseconds. The loop is blocked at most ``coarse_s`` per reply; the line is
serial anyway. ``paced=False`` (``--fast``) executes and answers at once.

Receive buffer (paced): ``RX_BUFFER_BYTES`` = 256 bytes per host port (67 ms of wire time at
38400) accepted ahead of the wire, as :mod:`servobus.sim.wire` states; the manual (7.1) gives
no buffer size and DYN232M has no flow control (RS-485, no RTS/CTS), so the size is a
servobus decision (docs/dyn232.md). Lost bytes cut packets, which the drives see as
framing/checksum errors. Replies still pending for a port that closes are dropped.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.device import Dyn232Line
from servobus.sim.wall_clock import RealtimeClock
from servobus.sim.wire import (
    COARSE_S,
    FINE_COARSE_S,
    RX_BUFFER_BYTES,
    SPIN_S,
    PacedLine,
    PacedPort,
    WireClock,
)
from servobus.transport.base import Direction

__all__ = ["BYTE_TIME_S", "COARSE_S", "FINE_COARSE_S", "MAX_PENDING_TAP", "RX_BUFFER_BYTES",
           "SPIN_S", "HostPort", "LineRunner", "WireClock"]

BYTE_TIME_S = c.wire_time_s(1)  # 10 bits at 38400 baud = 260.4 us
MAX_PENDING_TAP = 4096  # host bytes held for the tap until their packet completes


class HostPort(PacedPort):
    """One host connection on the line (TCP client, PTY, in-process stream)."""

    def __init__(self, deliver: Callable[[bytes], None]) -> None:
        super().__init__(deliver)
        self.framer = c.Framer()  # per port: two hosts' packets never mix mid-packet
        self.tap_pending = bytearray()  # host bytes of a packet not yet complete


class LineRunner(PacedLine[HostPort]):
    """Drives a :class:`Dyn232Line` in wall-clock time, paced at 38400 8N1 or not."""

    def __init__(
        self,
        line: Dyn232Line,
        clock: RealtimeClock | None = None,
        *,
        paced: bool = True,
        byte_time_s: float = BYTE_TIME_S,
        coarse_s: float = COARSE_S,
        spin_s: float = SPIN_S,
    ) -> None:
        super().__init__(line.drives, clock, paced=paced, coarse_s=coarse_s, spin_s=spin_s)
        self.line = line
        self.rx = WireClock(byte_time_s)  # host -> drives
        self.tx = WireClock(byte_time_s)  # drives -> host
        self.coarse_s = coarse_s
        self.spin_s = spin_s

    def open_port(self, deliver: Callable[[bytes], None]) -> HostPort:
        return HostPort(deliver)

    # ------------------------------------------------------------------ host bytes in
    def submit(self, port: HostPort, data: bytes) -> None:
        """Host bytes from ``port`` reached the line now (call on the loop's thread).

        Taps get host bytes a whole packet at a time (bytes of an incomplete packet wait in
        the port until it completes), so packets of two host ports never interleave there.
        """
        if not data:
            return
        if type(data) is not bytes:
            data = bytes(data)
        now = time.monotonic()
        taps = self.taps
        if not self.paced:
            self.clock.sync(now)
            if not taps and port.framer.whole_packet(data):  # the usual case, at once
                reply = self.line.handle_whole(data)
                if reply:
                    port.deliver(reply)
            else:
                for _, chunk, event in self._segments(port, data):
                    if taps:
                        self._tap(Direction.TX, chunk, now)
                    reply = self._handle(event)
                    if reply:
                        if taps:
                            self._tap(Direction.RX, reply, now)
                        port.deliver(reply)
            self.start()
            return
        self.start()
        self.clock.sync(now)
        data, start, _ = self._accept(port, data, now, self.rx)
        if not data:
            return
        bt = self.rx.byte_time_s
        for end, chunk, event in self._segments(port, data):
            t_done = start + end * bt
            self.clock.sync(t_done)  # the drives' time = arrival time of the last byte
            if taps:
                self.releases.at(t_done, self._tap_cb(Direction.TX, chunk, t_done))
            reply = self._handle(event)
            if reply:
                _, t_end = self.tx.send(len(reply), t_done)
                self._reply_at(port, reply, t_end)

    def _handle(self, event: bytes | c.FramerEvent) -> bytes:
        """Run one framed event; ``bytes`` stands for one whole, not yet decoded packet."""
        if type(event) is bytes:
            return self.line.handle_whole(event)
        assert not isinstance(event, bytes)
        return self.line.handle(event)

    def _segments(
        self, port: HostPort, data: bytes
    ) -> Iterator[tuple[int, bytes, bytes | c.FramerEvent]]:
        """Frame ``data``; yield (bytes of ``data`` used so far, bytes of the event, event).

        The first chunk includes the port's bytes held from earlier calls; bytes of a packet
        still incomplete at the end are held in ``port.tap_pending``. A chunk that is exactly
        one packet is yielded undecoded (event = its bytes, see :meth:`_handle`).
        """
        if not port.tap_pending and port.framer.whole_packet(data):
            yield len(data), data, data  # one packet, one chunk
            return
        seg = 0
        for i, event in self.line.events(data, port.framer):
            chunk = bytes(port.tap_pending) + data[seg : i + 1]
            port.tap_pending.clear()
            seg = i + 1
            yield seg, chunk, event
        if self.taps:  # bounded: a run of garbage is not kept forever
            port.tap_pending += data[seg:]
            del port.tap_pending[:-MAX_PENDING_TAP]

    def _tap_cb(self, direction: Direction, data: bytes, when: float) -> Callable[[], None]:
        return lambda: self._tap(direction, data, when)
