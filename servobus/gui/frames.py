"""The binary scope frame the server sends over the WebSocket (one message per frame).

Little-endian, 8-byte aligned so the page reads it with typed-array views, no copy::

    0   u8  version (1)          1  u8  kind (1 = scope frame)
    2   u8  channels             3  u8  flags (FLAG_*)
    4   u32 points
    8   f64 t_ref: time.monotonic() seconds of x = 0 (the trigger, or the newest sample)
    16  f64 sample rate, Hz (the lowest of the axes shown)
    24  u32 sequence number      28 u32 raw samples in the window
    32  f64 newest sample, s from t_ref
    40  f64 server send time, time.monotonic() seconds
    48  f64[points] x, seconds from t_ref (drive-side sample times)
    ..  f32[points] y of channel 0, then channel 1, ...

The page answers ``{"type": "ack", "seq": n}`` once it has drawn a frame; the server keeps
at most two frames unanswered (a slow page gets fewer frames, never a backlog) and measures
the delay from a sample's time to the ack (servobus.gui.scope_session).
"""

from __future__ import annotations

import struct
from array import array
from collections.abc import Sequence
from dataclasses import dataclass

VERSION = 1
KIND_SCOPE = 1
HEADER = struct.Struct("<BBBBIddIIdd")
assert HEADER.size == 48

FLAG_TRIGGERED = 1  # x = 0 is a trigger
FLAG_HOLDING = 2  # single capture done: the scope holds until re-armed
FLAG_PAIRS = 4  # two points (min, max) per bucket
FLAG_FREE_RUN = 8  # auto mode without a trigger: a rolling view


@dataclass(frozen=True)
class ScopeFrame:
    t_ref: float
    rate_hz: float
    seq: int
    raw_count: int
    newest: float
    sent: float
    flags: int
    x: Sequence[float]
    ys: Sequence[Sequence[float]]

    def encode(self) -> bytes:
        n = len(self.x)
        if any(len(y) != n for y in self.ys):
            raise ValueError("every channel needs as many points as x")
        parts = [HEADER.pack(VERSION, KIND_SCOPE, len(self.ys), self.flags, n, self.t_ref,
                             self.rate_hz, self.seq & 0xFFFFFFFF, self.raw_count, self.newest,
                             self.sent),
                 _as_array("d", self.x).tobytes()]
        parts += [_as_array("f", y).tobytes() for y in self.ys]
        return b"".join(parts)


def _as_array(code: str, values: Sequence[float]) -> array[float]:
    if isinstance(values, array) and values.typecode == code:
        return values
    return array(code, values)


def decode(data: bytes) -> ScopeFrame:
    """The inverse of :meth:`ScopeFrame.encode` (tests, benchmarks)."""
    (version, kind, nch, flags, n, t_ref, rate, seq, raw, newest,
     sent) = HEADER.unpack_from(data)
    if version != VERSION or kind != KIND_SCOPE:
        raise ValueError(f"not a scope frame (version {version}, kind {kind})")
    expected = HEADER.size + 8 * n + 4 * n * nch
    if len(data) != expected:
        raise ValueError(f"frame of {len(data)} bytes, expected {expected}")
    x = array("d", data[HEADER.size:HEADER.size + 8 * n])
    ys = []
    at = HEADER.size + 8 * n
    for _ in range(nch):
        ys.append(array("f", data[at:at + 4 * n]))
        at += 4 * n
    return ScopeFrame(t_ref, rate, seq, raw, newest, sent, flags, x, ys)
