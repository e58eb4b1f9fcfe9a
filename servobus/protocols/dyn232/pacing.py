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

Receive buffer (paced). Each host port may have at most ``RX_BUFFER_BYTES`` = 256 bytes
(67 ms of wire time) accepted but not yet arrived at the drives; bytes beyond that are lost,
as bytes are when a serial bridge's or UART's receive buffer overflows: DYN232M has no flow
control (RS-485, no RTS/CTS), and the manual (7.1) gives no buffer size, so the size is a
servobus decision (docs/dyn232.md). A host that waits for its replies, or writes no faster
than 38400 baud, never loses a byte; a flood costs the line at most 67 ms per host port,
and no memory. Lost bytes cut packets, which the drives see as framing/checksum errors.
Replies still pending for a port that closes are dropped (:meth:`LineRunner.close_port`).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator

from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.line import Dyn232Line
from servobus.sim.realtime import RealtimeClock
from servobus.sim.wire import COARSE_S, FINE_COARSE_S, SPIN_S, TimedReleases, WireClock
from servobus.transport.base import Direction, TraceHook

__all__ = ["BYTE_TIME_S", "COARSE_S", "FINE_COARSE_S", "MAX_PENDING_TAP", "RX_BUFFER_BYTES",
           "SPIN_S", "HostPort", "LineRunner", "WireClock"]

BYTE_TIME_S = c.wire_time_s(1)  # 10 bits at 38400 baud = 260.4 us
MAX_PENDING_TAP = 4096  # host bytes held for the tap until their packet completes
RX_BUFFER_BYTES = 256  # per host port, accepted ahead of the wire (see the module doc)


class HostPort:
    """One host connection on the line (TCP client, PTY, in-process stream)."""

    def __init__(self, deliver: Callable[[bytes], None]) -> None:
        self.framer = c.Framer()  # per port: two hosts' packets never mix mid-packet
        self._deliver = deliver
        self.tap_pending = bytearray()  # host bytes of a packet not yet complete
        self.closed = False
        self.pending = 0  # paced replies scheduled for this port, not yet released
        self.on_idle: Callable[[], None] | None = None  # called when ``pending`` drops to 0
        self.rx_queued = 0  # bytes accepted, not yet arrived (paced receive buffer)
        self.rx_inflight: deque[tuple[float, int]] = deque()  # (arrival of the last, count)
        self.rx_dropped = 0  # bytes lost to a full receive buffer

    def deliver(self, data: bytes) -> None:
        if not self.closed:
            self._deliver(data)


class LineRunner:
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
        self.line = line
        self.clock = clock if clock is not None else RealtimeClock(line.drives)
        self.paced = paced
        self.rx = WireClock(byte_time_s)  # host -> drives
        self.tx = WireClock(byte_time_s)  # drives -> host
        self.coarse_s = coarse_s
        self.spin_s = spin_s
        self.rx_buffer_bytes = RX_BUFFER_BYTES
        self.rx_dropped = 0  # bytes lost to full receive buffers, all ports
        self.taps: list[TraceHook] = []
        self.releases = TimedReleases(coarse_s=coarse_s, spin_s=spin_s)
        self.max_late_s = 0.0  # worst lateness of a release (diagnostics / benchmarks)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start the clock ticker and the release task on the running loop (idempotent)."""
        self.clock.start()
        if self.paced:
            self.releases.start()

    async def close(self) -> None:
        await self.clock.stop()
        await self.releases.close()

    def open_port(self, deliver: Callable[[bytes], None]) -> HostPort:
        return HostPort(deliver)

    def close_port(self, port: HostPort) -> None:
        """The host has gone: its pending replies are dropped (memory freed at once)."""
        port.closed = True
        port.on_idle = None
        if port.pending:
            port.pending = 0
            self.releases.drop(port)

    def add_tap(self, hook: TraceHook) -> None:
        """``hook(direction, bytes, monotonic time)`` for every byte of the line, in order."""
        self.taps.append(hook)

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
        data = self._admit(port, data, now)
        if not data:
            return
        start, end_all = self.rx.send(len(data), now)
        port.rx_inflight.append((end_all, len(data)))
        port.rx_queued += len(data)
        bt = self.rx.byte_time_s
        for end, chunk, event in self._segments(port, data):
            t_done = start + end * bt
            self.clock.sync(t_done)  # the drives' time = arrival time of the last byte
            if taps:
                self._at(t_done, None, self._tap_cb(Direction.TX, chunk, t_done))
            reply = self._handle(event)
            if reply:
                _, t_end = self.tx.send(len(reply), t_done)
                port.pending += 1
                self._at(t_end, port, self._release_cb(port, reply, t_end))

    def _admit(self, port: HostPort, data: bytes, now: float) -> bytes:
        """The part of ``data`` that fits the port's receive buffer (see the module doc)."""
        inflight = port.rx_inflight
        while inflight and inflight[0][0] <= now:
            port.rx_queued -= inflight.popleft()[1]
        room = self.rx_buffer_bytes - port.rx_queued
        if room >= len(data):
            return data
        lost = len(data) - max(room, 0)
        port.rx_dropped += lost
        self.rx_dropped += lost
        return data[:room] if room > 0 else b""

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

    # ------------------------------------------------------------------ timed release
    def _at(self, when: float, port: HostPort | None, action: Callable[[], None]) -> None:
        self.releases.at(when, action, port)

    def _release_cb(self, port: HostPort, reply: bytes, when: float) -> Callable[[], None]:
        def release() -> None:
            self.max_late_s = max(self.max_late_s, time.monotonic() - when)
            self._tap(Direction.RX, reply, when)
            port.pending -= 1
            port.deliver(reply)
            if not port.pending and port.on_idle is not None:
                port.on_idle()

        return release

    def _tap_cb(self, direction: Direction, data: bytes, when: float) -> Callable[[], None]:
        return lambda: self._tap(direction, data, when)

    def _tap(self, direction: Direction, data: bytes, when: float) -> None:
        for hook in self.taps:
            hook(direction, data, when)
