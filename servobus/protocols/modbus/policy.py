"""The transaction policy of the Modbus RTU client, in one class (deadlines, retries, gaps).

Kept apart from the client's mechanics so that a transaction manager shared by every
protocol can take its place without touching the reception code. Decisions (servobus's;
docs/modbus.md):

* Per-attempt deadline = request wire time + t3.5 (the device recognises the end of the
  request after t3.5 of silence, Serial Line v1.02 2.5.1.1) + reply wire time (the longer
  of the normal and the exception reply) + ``turnaround_s``. ``turnaround_s`` defaults to
  50 ms: spec 004 gives no response time, and USB-serial adapters add up to 16 ms of latency
  timer each way. ``timeout=`` replaces the whole per-attempt deadline.
* Reads are re-sent up to ``retries`` times (default 2). Writes are sent exactly once: the
  YZ-AIM writes that move the motor (0x0C/0x0D, 0x16/0x17, the cache 0x1A/0x1B) or start an
  action (0x14 save) must never be repeated, and settings are treated alike (docs/axis.md:
  "never for motion or settings"), so a lost reply to a write is reported, not retried.
* The host keeps t3.5 of silence on the line before each frame, after the last byte it
  sent or received (Serial Line 2.5.1.1: frames are separated by at least 3.5 characters).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from servobus.axis import checks
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.timing import DEFAULT_BAUD, inter_frame_gap_s, wire_time_s

DEFAULT_RETRIES = 2
DEFAULT_TURNAROUND_S = 0.05


@dataclass(frozen=True)
class RtuPolicy:
    """Deadlines, attempts and the inter-frame gap for one line; arguments checked here."""

    baud: int = DEFAULT_BAUD
    retries: int = DEFAULT_RETRIES
    turnaround_s: float = DEFAULT_TURNAROUND_S
    timeout: float | None = None
    gap_s: float = field(init=False)

    def __post_init__(self) -> None:
        checks.positive_int("baud", self.baud)
        checks.count("retries", self.retries)
        checks.non_negative_seconds("turnaround_s", self.turnaround_s)
        checks.optional_seconds("timeout", self.timeout)
        object.__setattr__(self, "gap_s", inter_frame_gap_s(self.baud))

    def deadline_s(self, request: C.Request, timeout: float | None = None) -> float:
        """Seconds one attempt waits for its reply after the request was handed over."""
        if timeout is not None:
            return checks.seconds("timeout", timeout)
        if self.timeout is not None:
            return self.timeout
        request_len = len(C.encode_request(request))
        reply_len = max(C.reply_length(request), C.EXCEPTION_FRAME_LENGTH)
        return (wire_time_s(request_len + reply_len, self.baud) + self.gap_s
                + self.turnaround_s)

    def attempts(self, request: C.Request, retries: int | None = None) -> int:
        """1 + retries for a read; 1 for every write (never re-sent)."""
        if retries is not None:
            checks.count("retries", retries)
        if not isinstance(request, C.ReadHoldingRequest):
            return 1
        return 1 + (self.retries if retries is None else retries)

    def worst_case_s(self, request: C.Request) -> float:
        """Longest a call can take before DriveTimeout (gaps excluded)."""
        return self.deadline_s(request) * self.attempts(request)
