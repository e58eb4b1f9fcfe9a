"""Modbus RTU traffic for people: ``servobus decode --protocol modbus`` / ``sniff``, traces.

Pure (no I/O, no clock): bytes in, events out. Frames are cut from the byte stream by
content with the eager :class:`~servobus.protocols.modbus.framer.GapFramer` (a capture or a
hex string carries no timing; a caller that has timestamps may pass them to
:meth:`RtuStreamDecoder.iter_feed`). Register addresses are named from the YZ-AIM register
table (``servobus.families.yzaim.registers``).

Direction. A read request is 8 bytes and its reply 5 + 2n, a write-multiple request
9 + 2n and its reply 8, an exception reply has bit 7 of its function set: the codec tells
them apart by length (``codec.decode_frame``). A write-single reply is an echo of its
request (Modbus Application Protocol 6.6): a write-single frame identical to the frame just
before it is shown as the drive's echo, any other one as the host's request.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

from servobus.errors import ProtocolError
from servobus.families.yzaim import registers as Y
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.framer import GapFramer, TimedFrame
from servobus.protocols.modbus.timing import DEFAULT_BAUD, char_time_s
from servobus.sniff import ByteDecoder, ErrorEvent, raw_column

#: Register address -> name, for describe().
REGISTER_NAMES: Mapping[int, str] = {r.address: r.name for r in Y.REGISTERS}
_ECHO_TAG = " (request or echo)"


@dataclass(frozen=True)
class RtuFrameEvent:
    """One RTU frame with a good CRC, its direction and its meaning (a sniff event and a
    client trace item: ``describe`` is what ``transport.trace.format_event`` prints)."""

    raw: bytes
    from_drive: bool
    text: str

    is_error = False

    def describe(self, from_drive: bool | None = None) -> str:
        return self.text

    def as_dict(self) -> dict[str, object]:
        return {"raw": self.raw.hex(" "),
                "direction": "drive->host" if self.from_drive else "host->drive",
                "text": self.text}

    def lines(self, prefix: str = "", width: int = 21) -> list[str]:
        return [f"{prefix}{raw_column(self.raw.hex(' '), width)}{self.text}"]


def frame_event(raw: bytes, previous: bytes | None = None) -> RtuFrameEvent:
    """The event of one frame with a good CRC (ProtocolError if it is not a frame)."""
    frame = C.decode_frame(raw)
    text = C.describe(raw, REGISTER_NAMES)
    if isinstance(frame, C.WriteSingleRequest):
        echo = raw == previous
        text = text.replace(_ECHO_TAG, " (echo)" if echo else "")
        return RtuFrameEvent(raw, echo, text)
    from_drive = isinstance(frame, C.ReadHoldingReply | C.WriteMultipleReply | C.ExceptionReply)
    return RtuFrameEvent(raw, from_drive, text)


def request_event(raw: bytes) -> RtuFrameEvent:
    """A frame the host sends (client trace)."""
    return RtuFrameEvent(raw, False, C.describe(raw, REGISTER_NAMES).replace(_ECHO_TAG, ""))


def reply_event(raw: bytes) -> RtuFrameEvent:
    """A frame a drive sends (client trace)."""
    return RtuFrameEvent(raw, True, C.describe(raw, REGISTER_NAMES).replace(_ECHO_TAG,
                                                                              " (echo)"))


class RtuStreamDecoder:
    """Feed line bytes in any chunking; get frame and error events in line order."""

    def __init__(self, baud: int = DEFAULT_BAUD) -> None:
        self._framer = GapFramer(baud, eager=True)
        self._char_s = char_time_s(baud)
        self._t = 0.0
        self._previous: bytes | None = None

    def feed(self, data: bytes | bytearray) -> list[RtuFrameEvent | ErrorEvent]:
        return list(self.iter_feed(data))

    def iter_feed(self, data: bytes | bytearray,
                  t: float | None = None) -> Iterator[RtuFrameEvent | ErrorEvent]:
        """``t``: when the chunk's last byte arrived (seconds, any origin); None: no timing,
        frames are cut by content alone."""
        if not data:
            return
        if t is None:  # no silence between chunks: the content split decides
            t = self._t + len(data) * self._char_s
        self._t = t
        yield from self._events(lambda: self._framer.feed(data, t))

    def finish(self) -> list[RtuFrameEvent | ErrorEvent]:
        """End of input: the pending run is closed as if a silence followed."""
        return list(self._events(lambda: self._framer.flush(None)))

    def _events(self, step: Callable[[], list[TimedFrame]]
                ) -> Iterator[RtuFrameEvent | ErrorEvent]:
        framer = self._framer
        crc0, dropped0 = framer.crc_errors, framer.discarded
        frames = step()
        if framer.discarded != dropped0:
            n = framer.discarded - dropped0
            kind = "checksum" if framer.crc_errors != crc0 else "framing"
            what = "failed the CRC" if kind == "checksum" else "are not a frame"
            yield ErrorEvent(kind, f"{n} byte(s) dropped: they {what}")
        for timed in frames:
            try:
                event = frame_event(timed.raw, self._previous)
            except ProtocolError as exc:
                yield ErrorEvent("framing", str(exc), timed.raw)
                self._previous = None
                continue
            self._previous = None if event.from_drive else timed.raw
            yield event


DECODER = ByteDecoder("modbus", "Modbus RTU", RtuStreamDecoder)  # TTL/RS-485 line
