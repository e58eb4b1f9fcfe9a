"""EasyCan: the CAN 2.0A protocol of YZ-AIM integrated servo motors (manual section 5).

``functions`` holds the one table (function codes, frame lengths, error codes),
``messages`` the frozen dataclasses, ``codec`` (arbitration id, data) <-> messages in both
directions, ``describe`` one line per frame for decode/sniff. Registers, ranges and units
are the YZ-AIM family's (servobus.families.yzaim).
"""

from servobus.protocols.easycan.codec import (
    MalformedRequest,
    answers,
    decode,
    decode_reply,
    decode_request,
    encode,
    expects_reply,
)
from servobus.protocols.easycan.describe import describe, describe_frame
from servobus.protocols.easycan.functions import (
    HOST_ADDRESS,
    CacheKind,
    ErrorCode,
    Function,
)
from servobus.protocols.easycan.messages import (
    ClearPosition,
    EmergencyStop,
    EmergencyStopReply,
    ErrorReply,
    Message,
    PositionCacheWrite,
    PositionReply,
    ReadMultipleReply,
    ReadMultipleRequest,
    ReadReply,
    ReadRequest,
    Reply,
    Request,
    WriteReply,
    WriteRequest,
)

__all__ = [
    "HOST_ADDRESS",
    "CacheKind",
    "ClearPosition",
    "EmergencyStop",
    "EmergencyStopReply",
    "ErrorCode",
    "ErrorReply",
    "Function",
    "MalformedRequest",
    "Message",
    "PositionCacheWrite",
    "PositionReply",
    "ReadMultipleReply",
    "ReadMultipleRequest",
    "ReadReply",
    "ReadRequest",
    "Reply",
    "Request",
    "WriteReply",
    "WriteRequest",
    "answers",
    "decode",
    "decode_reply",
    "decode_request",
    "describe",
    "describe_frame",
    "encode",
    "expects_reply",
]
