"""The EasyCan codec's public names in one namespace (``from ... import api as easycan``).

The package ``__init__`` only declares registry tables (docs/architecture.md), so the codec's
messages, functions and describe helpers are gathered here instead.
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
