"""The timing of the Modbus RTU client in one place: per-attempt deadline and frame gap.

Retries, late replies, stats and trace are the shared
:class:`~servobus.link.transaction.TransactionManager`'s; this class only knows what RTU
timing adds. Decisions (servobus's; docs/modbus.md):

* Per-attempt deadline = request wire time + t3.5 (the device recognises the end of the
  request after t3.5 of silence, Serial Line v1.02 2.5.1.1) + reply wire time (the longer
  of the normal and the exception reply) + ``turnaround_s``. ``turnaround_s`` defaults to
  50 ms: spec 004 gives no response time, and USB-serial adapters add up to 16 ms of latency
  timer each way. ``timeout=`` replaces the whole per-attempt deadline.
* Reads are re-sent (``retries``, default 2); writes are sent exactly once: the YZ-AIM
  writes that move the motor (0x0C/0x0D, 0x16/0x17, the cache 0x1A/0x1B) or start an action
  (0x14 save) must never be repeated, and settings are treated alike (docs/axis.md).
* The host keeps t3.5 of silence on the line before each frame, after the last byte it
  sent or received (Serial Line 2.5.1.1: frames are separated by at least 3.5 characters).
  ``frame_gap_s`` sets another silence (a device that needs a longer pause between
  messages; 0 for a link that is no wire, such as the unpaced in-process line).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from servobus import checks
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.timing import DEFAULT_BAUD, inter_frame_gap_s, wire_time_s

DEFAULT_TURNAROUND_S = 0.05


@dataclass(frozen=True)
class RtuPolicy:
    """Deadlines and the inter-frame gap for one line; arguments checked here."""

    baud: int = DEFAULT_BAUD
    turnaround_s: float = DEFAULT_TURNAROUND_S
    timeout: float | None = None
    frame_gap_s: float | None = None  # None: t3.5 at ``baud``
    gap_s: float = field(init=False)  # the silence kept before each frame

    def __post_init__(self) -> None:
        checks.positive_int("baud", self.baud)
        checks.non_negative_seconds("turnaround_s", self.turnaround_s)
        checks.optional_seconds("timeout", self.timeout)
        gap = inter_frame_gap_s(self.baud) if self.frame_gap_s is None else \
            checks.non_negative_seconds("frame_gap_s", self.frame_gap_s)
        object.__setattr__(self, "gap_s", gap)

    def deadline_s(self, request: C.Request, timeout: float | None = None) -> float:
        """Seconds one attempt waits for its reply after the request has left."""
        if timeout is not None:
            return checks.seconds("timeout", timeout)
        if self.timeout is not None:
            return self.timeout
        request_len = len(C.encode_request(request))
        reply_len = max(C.reply_length(request), C.EXCEPTION_FRAME_LENGTH)
        return (wire_time_s(request_len + reply_len, self.baud)
                + inter_frame_gap_s(self.baud) + self.turnaround_s)
