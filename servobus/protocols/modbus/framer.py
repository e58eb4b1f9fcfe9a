"""Cut an RTU byte stream into frames. RTU has no delimiter: a frame ends at 3.5 characters of
silence (Modbus over Serial Line v1.02 section 2.5.1.1), and only the CRC tells a frame from
noise. Two framers, neither of which ever returns a frame that fails its CRC:

* :class:`GapFramer` for a virtual line or a sniffer, which see both directions and do not
  know what comes next: fed ``(bytes, timestamp)`` chunks, it closes a frame at a silence
  of t3.5 and splits what lies between two silences by content (frame lengths predicted
  from the function code, confirmed by the CRC), so frames sent back to back without the
  gap, garbage before or between frames and a frame cut short all resynchronise.
* :class:`ReplyFramer` for a host with one request outstanding: it knows the address,
  function and length of the only valid answers (the normal reply or the 5-byte exception),
  returns the reply as soon as its last byte is in, and skips anything else.

Counters (both framers): ``discarded`` counts every byte not delivered in a frame;
``crc_errors`` counts dropped runs that had the shape of a frame (GapFramer: a run of 4 or
more bytes that ends at a silence, or whose length its own first bytes predict; ReplyFramer:
a run with the expected address, function and length) but failed the CRC.
"""

from __future__ import annotations

from dataclasses import dataclass

from servobus.errors import ArgumentRangeError, ProtocolError
from servobus.protocols.modbus.codec import (
    EXCEPTION_FLAG,
    EXCEPTION_FRAME_LENGTH,
    FIXED_FRAME_LENGTH,
    MAX_FRAME,
    MIN_FRAME,
    Function,
    ReadHoldingRequest,
    Reply,
    Request,
    decode_reply,
    expects_reply,
    reply_length,
)
from servobus.protocols.modbus.crc import crc_ok, good_lengths
from servobus.protocols.modbus.timing import (
    BITS_PER_CHAR,
    DEFAULT_BAUD,
    char_time_s,
    inter_frame_gap_s,
)

_NEED_MORE = -1
_READ = int(Function.READ_HOLDING_REGISTERS)
_WRITE_SINGLE = int(Function.WRITE_SINGLE_REGISTER)
_WRITE_MULTIPLE = int(Function.WRITE_MULTIPLE_REGISTERS)


@dataclass(frozen=True)
class TimedFrame:
    """A frame with a good CRC and the timestamp of the chunk that completed it."""

    raw: bytes
    time: float


def _lengths(buf: bytearray, i: int, decide: bool,
             requests_only: bool) -> tuple[list[int], bool]:
    """Frame lengths the bytes at ``buf[i:]`` can have, and whether more bytes could add
    one. ``decide``: no byte will follow that could change the answer (a silence follows,
    or more than a frame's worth is buffered); a function code whose frame length the
    codec does not know then takes every length that passes the CRC."""
    n = len(buf)
    if n - i < 2:
        return [], not decide
    function = buf[i + 1]
    if function & EXCEPTION_FLAG:
        return ([] if requests_only else [EXCEPTION_FRAME_LENGTH]), False
    if function == _READ:  # request 8, reply 5 + byte count
        if requests_only or i + 2 >= n:
            return [FIXED_FRAME_LENGTH], not requests_only
        return [FIXED_FRAME_LENGTH, 5 + buf[i + 2]], False
    if function == _WRITE_SINGLE:
        return [FIXED_FRAME_LENGTH], False
    if function == _WRITE_MULTIPLE:  # request 9 + byte count, reply 8
        if i + 6 >= n:
            return ([] if requests_only else [FIXED_FRAME_LENGTH]), True
        return ([] if requests_only else [FIXED_FRAME_LENGTH]) + [9 + buf[i + 6]], False
    if decide:
        if requests_only:  # a device: a frame of unknown length is what the silence ends
            return [n - i], False
        return good_lengths(buf, i, MIN_FRAME, MAX_FRAME), False
    return [], True


class GapFramer:
    """Frames from timestamped chunks of a byte stream (a virtual line, a sniffer).

    ``feed(data, t)``: ``t`` is when the chunk's last byte was received. The silence before
    the chunk is taken as ``t - wire_time(len(data)) - t_previous``: exact on a paced line,
    an underestimate when a transport batches bytes - then frames sent without a gap arrive
    in one run, which the content split still separates. A silence of t3.5 closes the
    pending run; :meth:`flush` closes it when no chunk follows (call it at :attr:`deadline`).

    ``eager=True`` also returns a frame as soon as its last byte is in and its CRC checks,
    without waiting for the silence (a virtual drive answering at once); unknown function
    codes, whose length only the silence tells, and bytes that read as two frames of
    different lengths still wait for it. ``requests_only=True`` reads only the request
    layouts (a device's receiver): a read is then always 8 bytes and a write-multiple
    9 + byte count, which removes the request/reply ambiguity of both (with both
    directions, an eager framer would take a read request starting at 0x02xx whose CRC
    ends in 0x00 for a one-register reply one byte short; YZ-AIM registers are 0x00-0x1D).
    It also takes a frame of an unknown function code only as the whole run up to the
    silence, as a device does (Serial Line 2.5.1.1), never a CRC match inside a run: the
    5 bytes ``03 00 02 00 01`` inside a read of register 0x0002 pass the CRC, and a
    corrupted read must not become a frame for device 3.
    """

    def __init__(self, baud: int = DEFAULT_BAUD, *, bits_per_char: int = BITS_PER_CHAR,
                 eager: bool = False, requests_only: bool = False) -> None:
        self.gap_s = inter_frame_gap_s(baud, bits_per_char)
        self._char_s = char_time_s(baud, bits_per_char)
        self.eager = eager
        self.requests_only = requests_only
        self._buf = bytearray()
        self._last_t = 0.0
        self.frames = 0
        self.crc_errors = 0
        self.discarded = 0

    @property
    def pending(self) -> int:
        """Bytes held for a frame not closed yet."""
        return len(self._buf)

    @property
    def deadline(self) -> float | None:
        """When the pending bytes close if nothing more arrives (None: nothing pending)."""
        return self._last_t + self.gap_s if self._buf else None

    def feed(self, data: bytes | bytearray | memoryview, t: float) -> list[TimedFrame]:
        out: list[TimedFrame] = []
        if not data:
            return out
        if self._buf and t - len(data) * self._char_s - self._last_t >= self.gap_s:
            self._split(True, out)
        self._buf += data
        self._last_t = t
        if self.eager or len(self._buf) > MAX_FRAME:
            self._split(False, out)
        return out

    def flush(self, now: float | None = None) -> list[TimedFrame]:
        """Close the pending run if the line has been silent for t3.5 at ``now``; with
        ``now=None`` close it unconditionally (end of stream)."""
        out: list[TimedFrame] = []
        # the same sum as :attr:`deadline` (``now - last >= gap`` missed it by rounding)
        if self._buf and (now is None or now >= self._last_t + self.gap_s):
            self._split(True, out)
        return out

    def _split(self, final: bool, out: list[TimedFrame]) -> None:
        """Take frames from the buffer front; ``final``: a silence follows the buffer."""
        buf = self._buf
        n = len(buf)
        i = 0
        run: int | None = None  # start of bytes being dropped
        while i < n:
            length = self._match(i, final)
            if length == _NEED_MORE:
                break
            if length:
                if run is not None:
                    self._drop(run, i, at_silence=False)
                    run = None
                out.append(TimedFrame(bytes(buf[i:i + length]), self._last_t))
                self.frames += 1
                i += length
            else:
                if run is None:
                    run = i
                i += 1
        if final:
            if run is not None:
                self._drop(run, n, at_silence=True)
            buf.clear()
            return
        if run is not None and n - run > MAX_FRAME:  # hold no more than one frame's worth
            self._drop(run, i, at_silence=False)
            run = None
        del buf[:i if run is None else run]

    def _match(self, i: int, final: bool) -> int:
        """Length of a frame with a good CRC at ``i``; 0 if none; _NEED_MORE to wait."""
        buf = self._buf
        n = len(buf)
        decide = final or n - i > MAX_FRAME
        lengths, wait = _lengths(buf, i, decide, self.requests_only)
        good = []
        for length in set(lengths):
            if not MIN_FRAME <= length <= MAX_FRAME:
                continue
            if i + length > n:
                wait = True
            elif crc_ok(buf[i:i + length]):
                good.append(length)
        if len(good) == 1:
            return good[0]
        if not decide and (wait or good):
            return _NEED_MORE  # nothing yet, or two readings: let the silence decide
        if not good:
            return 0
        # Two lengths pass (a CRC stays 0 over a trailing 0x00, so a frame whose CRC ends
        # in 0x00 also passes one byte shorter): prefer the frame the silence ends, then
        # one followed by another good frame, then the shorter.
        return min(good, key=lambda k: (not (final and i + k == n),
                                        not self._frame_at(i + k), k))

    def _frame_at(self, j: int) -> bool:
        """A frame with a good CRC starts at ``j`` (or the buffer ends there)."""
        buf = self._buf
        n = len(buf)
        if j >= n:
            return True
        lengths, _ = _lengths(buf, j, True, self.requests_only)
        return any(k >= MIN_FRAME and j + k <= n and crc_ok(buf[j:j + k]) for k in lengths)

    def _drop(self, start: int, end: int, *, at_silence: bool) -> None:
        size = end - start
        self.discarded += size
        predicted = _lengths(self._buf, start, False, self.requests_only)[0]
        if size >= MIN_FRAME if at_silence else size in predicted:
            self.crc_errors += 1


class ReplyFramer:
    """The reply to one outstanding request, taken from a byte stream in any chunking.

    Only two frames can answer ``request``: its normal reply (``reply_length(request)``
    bytes) or the 5-byte exception reply, both from the request's address. Bytes that
    cannot start one of them are skipped; a candidate that fails its CRC is counted and
    skipped by one byte (so a reply starting inside it is still found); a frame with a good
    CRC that does not answer the request (a late reply to an earlier one) is counted in
    ``unexpected`` and skipped whole. Modbus RTU has no transaction id: a late reply that
    is identical in shape to the expected one cannot be told from it, so a host should drop
    stale input before sending. A half-duplex adapter that echoes the host's own bytes must
    be handled by the transport (a write-single request equals its reply).
    """

    def __init__(self, request: Request | None = None) -> None:
        self._buf = bytearray()
        self._request: Request | None = None
        self.crc_errors = 0
        self.discarded = 0
        self.unexpected = 0
        if request is not None:
            self.expect(request)

    def expect(self, request: Request) -> None:
        """Arm for the reply to ``request``; bytes still buffered are discarded."""
        if not expects_reply(request):
            raise ArgumentRangeError("a broadcast request (address 0) gets no reply")
        self.discarded += len(self._buf)
        self._buf.clear()
        self._request = request

    @property
    def pending(self) -> int:
        """Bytes held that may still start the answer (0 after a reply or a skipped run; a
        lone byte that is not the request's address cannot start it)."""
        buf = self._buf
        request = self._request
        if len(buf) == 1 and request is not None and buf[0] != request.address:
            return 0
        return len(buf)

    @property
    def needed(self) -> int:
        """Bytes that can be read without reading past the reply (at least 1). After a feed
        the buffer front is always a plausible start of the answer."""
        request = self._request
        buf = self._buf
        length = EXCEPTION_FRAME_LENGTH
        if request is not None and len(buf) >= 2 and buf[1] == request.function:
            length = reply_length(request)
        return max(1, length - len(buf))

    def feed(self, data: bytes | bytearray | memoryview) -> Reply | None:
        """The reply once complete (an ExceptionReply is a reply too), else None."""
        request = self._request
        if request is None:
            self.discarded += len(data)
            return None
        buf = self._buf
        buf += data
        while len(buf) >= 2:
            length = self._expected_length(request)
            if not length:
                self.discarded += 1
                del buf[:1]
                continue
            if len(buf) < length:
                return None
            frame = bytes(buf[:length])
            if not crc_ok(frame):
                self.crc_errors += 1
                self.discarded += 1
                del buf[:1]
                continue
            try:
                reply = decode_reply(frame, request)
            except ProtocolError:
                self.unexpected += 1
                self.discarded += length
                del buf[:length]
                continue
            del buf[:length]
            self._request = None
            return reply
        return None

    def _expected_length(self, request: Request) -> int:
        """Length of the answer starting at the buffer front, or 0 if none can start there."""
        buf = self._buf
        if buf[0] != request.address:
            return 0
        if buf[1] == request.function | EXCEPTION_FLAG:
            return EXCEPTION_FRAME_LENGTH
        if buf[1] != request.function:
            return 0
        if isinstance(request, ReadHoldingRequest) and len(buf) >= 3 \
                and buf[2] != 2 * request.count:
            return 0
        return reply_length(request)
