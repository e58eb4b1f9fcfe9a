"""The virtual RTU line in wall-clock time: bytes paced at the baud rate, frames by silence.

Model (servobus decisions, docs/modbus.md; Modbus over Serial Line v1.02 2.5.1.1):

* One half-duplex wire (RS-485 multi-drop, 8N1 at ``baud``; 520.8 us per byte at 19200):
  host bytes and replies take turns on the same :class:`~servobus.sim.wire.WireClock`. A
  chunk handed over at ``t`` starts at ``max(t, wire free)``; byte ``i`` has arrived
  ``(i + 1)`` byte times later. A host frame sent while a reply is still on the wire waits
  for it (a real bus would garble both; hosts wait for replies, so only a misbehaving host
  sees the difference).
* Each host port (TCP client, PTY, in-process stream) has its own device-side framer (an
  eager :class:`~servobus.protocols.modbus.framer.GapFramer` reading request layouts), so two
  hosts never corrupt each other's frames. A frame is executed at the instant its last byte
  arrived (the drives' time is synced to it); one whose length only the silence tells (an
  unknown function code) at t3.5 after its last byte.
* A device answers after t3.5 of silence (that is when a Modbus device knows the request
  has ended), so a reply starts ``t3.5`` after the request's last byte and is handed to the
  host when its own last byte has left: a read of one register takes 8 + 7 bytes + t3.5 =
  9.6 ms at 19200 from request to reply.
* Receive buffer: ``RX_BUFFER_BYTES`` = 256 bytes per host port accepted ahead of the wire
  (one maximal RTU frame, 133 ms at 19200), as :mod:`servobus.sim.wire` states (RTU has no
  flow control).
* ``paced=False`` (``--fast``, ``fast=1``): executed and answered at once.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from servobus.protocols.modbus.crc import crc_ok
from servobus.protocols.modbus.framer import GapFramer
from servobus.protocols.modbus.timing import DEFAULT_BAUD, char_time_s, inter_frame_gap_s
from servobus.sim.wall_clock import Clocked, RealtimeClock
from servobus.sim.wire import COARSE_S, RX_BUFFER_BYTES, SPIN_S, PacedLine, PacedPort, WireClock
from servobus.transport.base import Direction

__all__ = ["RX_BUFFER_BYTES", "FrameHandler", "RtuLineRunner", "RtuPort", "whole_request"]

_READ, _WRITE_SINGLE, _WRITE_MULTIPLE = 0x03, 0x06, 0x10


class FrameHandler(Protocol):
    """The device side of the line: one request frame (good CRC) in, reply bytes out."""

    @property
    def drives(self) -> Sequence[Clocked]: ...

    def handle(self, raw: bytes) -> bytes: ...

    def note_dropped(self, crc_errors: int, discarded: int) -> None:
        """Bytes the framers dropped: ``crc_errors`` runs shaped like a frame that failed
        the CRC, ``discarded`` bytes in all."""


class RtuPort(PacedPort):
    """One host on the line: its framer, its pending replies, its receive buffer."""

    def __init__(self, deliver: Callable[[bytes], None], baud: int) -> None:
        super().__init__(deliver)
        self.framer = GapFramer(baud, eager=True, requests_only=True)
        self.flush_at: float | None = None  # when the framer's pending run closes
        self.noted = (0, 0)  # framer counters (crc_errors, discarded) already reported


def whole_request(data: bytes) -> bool:
    """``data`` is exactly one request frame of a known function with a good CRC."""
    n = len(data)
    if n < 8:
        return False
    function = data[1]
    if function in (_READ, _WRITE_SINGLE):
        expected = 8
    elif function == _WRITE_MULTIPLE:
        expected = 9 + data[6]
    else:
        return False
    return n == expected and crc_ok(data)


class RtuLineRunner(PacedLine[RtuPort]):
    """Runs a :class:`FrameHandler` in wall-clock time, paced at ``baud`` 8N1 or not."""

    def __init__(self, line: FrameHandler, *, paced: bool = True, baud: int = DEFAULT_BAUD,
                 clock: RealtimeClock | None = None, coarse_s: float = COARSE_S,
                 spin_s: float = SPIN_S) -> None:
        super().__init__(line.drives, clock, paced=paced, coarse_s=coarse_s, spin_s=spin_s)
        self.line = line
        self.baud = baud
        self.wire = WireClock(char_time_s(baud))  # half duplex: both directions
        self.gap_s = inter_frame_gap_s(baud)

    def open_port(self, deliver: Callable[[bytes], None]) -> RtuPort:
        return RtuPort(deliver, self.baud)

    def close_port(self, port: RtuPort) -> None:
        """The host has gone: its pending replies and armed flush are dropped."""
        if port.flush_at is not None:
            port.flush_at = None
            if not port.pending:  # else the base class drops the port's actions
                self.releases.drop(port)
        super().close_port(port)

    # ------------------------------------------------------------------ host bytes in
    def submit(self, port: RtuPort, data: bytes) -> None:
        """Host bytes from ``port`` reached the line now (call on the loop's thread)."""
        if not data or port.closed:
            return
        data = bytes(data)
        now = time.monotonic()
        self.start()
        if not self.paced:
            self.clock.sync(now)
            if not port.framer.pending and whole_request(data):
                self._execute(port, data, now)
            else:
                for frame in port.framer.feed(data, now):
                    self._execute(port, frame.raw, now)
                self._note(port)
            self._arm_flush(port)
            return
        self.clock.sync(now)
        data, start, end = self._accept(port, data, now, self.wire)
        if not data:
            return
        if not port.framer.pending and whole_request(data):
            self._execute(port, data, end)
        else:
            bt = self.wire.byte_time_s
            for i in range(len(data)):  # each byte at its own arrival time
                for frame in port.framer.feed(data[i:i + 1], start + (i + 1) * bt):
                    self._execute(port, frame.raw, frame.time)
            self._note(port)
        self._arm_flush(port)

    # ------------------------------------------------------------------ frames
    def _execute(self, port: RtuPort, raw: bytes, t_end: float) -> None:
        """Run one request frame whose last byte arrived at ``t_end``."""
        self.clock.sync(t_end)  # the drives' time = arrival of the frame's last byte
        taps = self.taps
        reply = self.line.handle(raw)
        if not self.paced:
            if taps:
                self._tap(Direction.TX, raw, t_end)
            if reply:
                if taps:
                    self._tap(Direction.RX, reply, t_end)
                port.deliver(reply)
            return
        if taps:
            self.releases.at(t_end, lambda: self._tap(Direction.TX, raw, t_end), port)
        if reply:
            _, t_out = self.wire.send(len(reply), t_end + self.gap_s)
            self._reply_at(port, reply, t_out)

    def _note(self, port: RtuPort) -> None:
        framer = port.framer
        crc, dropped = port.noted
        if framer.crc_errors != crc or framer.discarded != dropped:
            self.line.note_dropped(framer.crc_errors - crc, framer.discarded - dropped)
            port.noted = (framer.crc_errors, framer.discarded)

    def _arm_flush(self, port: RtuPort) -> None:
        """Close a run only the silence can end (unknown function, garbage) at t3.5."""
        deadline = port.framer.deadline
        if deadline is None or port.flush_at == deadline:
            return
        port.flush_at = deadline
        if self.paced:
            self.releases.at(deadline, lambda: self._flush(port, deadline), port)
        else:
            asyncio.get_running_loop().call_later(
                max(0.0, deadline - time.monotonic()), self._flush, port, deadline)

    def _flush(self, port: RtuPort, deadline: float) -> None:
        if port.closed or port.flush_at != deadline:
            return  # more bytes came: a later flush is armed
        port.flush_at = None
        now = time.monotonic()
        for frame in port.framer.flush(max(deadline, now)):
            # the silence ended the frame: the device answers from now on
            self._execute(port, frame.raw, deadline - self.gap_s if self.paced else now)
        self._note(port)
