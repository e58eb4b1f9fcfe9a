"""DYN CAN frames for people (``servobus decode ID#DATA``/``sniff --can``, the GUI's monitor).

Direction comes from the frame's shape (replies reuse the request's identifier, so the
data length against the function table tells them apart; :func:`codec.describe`).
"""

from __future__ import annotations

from servobus.errors import ProtocolError
from servobus.protocols.dyncan import codec as dyncan
from servobus.sniff import CanDecoder, ErrorEvent, FrameEvent


def can_length_error(frame: dyncan.Frame) -> str | None:
    """Why the frame's data length fits neither the request nor the reply of its function.

    The function table gives both lengths (DYN CAN specification 1.2A, section 5); a frame
    that fits neither is reported, never decoded with made-up data (an empty 0x0E frame is not
    General_Read 0). DMM-internal functions (0x0F, 0x1B) are shown as they are.
    """
    spec = frame.spec
    shapes: list[tuple[str, tuple[int, int]]] = []
    if spec.kind is not dyncan.Kind.INTERNAL:  # internal functions are never host requests
        lo, hi = spec.sent
        shapes.append(("request", (lo, max(hi, spec.dummy))))  # dummy bytes of a read
    if spec.reply is not None:
        shapes.append(("reply", spec.returned))
    n = len(frame.data)
    if not shapes or any(lo <= n <= hi for _, (lo, hi) in shapes):
        return None
    allowed = " or ".join(f"{lo if lo == hi else f'{lo}..{hi}'} ({what})"
                          for what, (lo, hi) in shapes)
    return f"{spec.function.name} takes {allowed} data byte(s); this frame has {n}"


def can_event(arbitration_id: int, data: bytes) -> FrameEvent | ErrorEvent:
    raw_text = f"{arbitration_id:03x}#{bytes(data).hex()}"
    try:
        frame = dyncan.decode(arbitration_id, data)
    except ProtocolError as exc:
        return ErrorEvent("frame", str(exc), bytes(data), raw_text)
    problem = can_length_error(frame)
    if problem is not None:
        return ErrorEvent("frame", problem, bytes(data), raw_text)
    return FrameEvent(arbitration_id, bytes(data), dyncan.describe(frame))


DECODER = CanDecoder("dyncan", "DYN CAN", can_event)
