"""EasyCan frames for people (``servobus decode ID#DATA``, ``sniff``, the GUI's monitor).

Direction comes from the identifier: the host's 0xFF carries replies, 0x0xx/0x1xx/0x3xx
requests (manual 5.3). Each frame is decoded on its own, so a 4-byte reply reads as the
position-cache reply (the codec's default; a one-register 0x12 reply has the same shape).
"""

from __future__ import annotations

from servobus.errors import ProtocolError
from servobus.protocols.easycan.codec import decode
from servobus.protocols.easycan.describe import describe
from servobus.sniff import CanDecoder, ErrorEvent, FrameEvent


def can_event(arbitration_id: int, data: bytes) -> FrameEvent | ErrorEvent:
    raw_text = f"{arbitration_id:03x}#{bytes(data).hex()}"
    try:
        message = decode(arbitration_id, data)
    except ProtocolError as exc:
        return ErrorEvent("frame", str(exc), bytes(data), raw_text)
    return FrameEvent(arbitration_id, bytes(data), describe(message))


DECODER = CanDecoder("easycan", "EasyCan", can_event)
