"""The EasyCan client's transaction policy, in one class so it can be swapped for a shared one.

Decisions (docs/easycan.md; the manual gives no timing):

* Per-attempt deadline 50 ms: a motor answers within a frame time (about 0.1 ms at
  1 Mbit/s) plus its firmware's turn-around; the margin covers USB adapters, socketcand
  over TCP and a loaded host.
* At most 2 re-sends, only for commands marked ``retry_safe`` (commands.py: reads and
  setting writes); everything else is sent exactly once and a missing reply is a
  DriveTimeout that says so.
* A reply that comes after its attempt timed out is owed to nobody: it is dropped, and the
  next read of the same kind first waits up to ``late_reply_s`` for the owed replies
  (servobus.axis.late_replies), so a value is never older than its call.
"""

from __future__ import annotations

from dataclasses import dataclass

from servobus.axis import checks
from servobus.axis.late_replies import DEFAULT_LATE_REPLY_S

DEFAULT_TIMEOUT_S = 0.05
DEFAULT_RETRIES = 2


@dataclass(frozen=True)
class TransactionPolicy:
    timeout: float = DEFAULT_TIMEOUT_S
    retries: int = DEFAULT_RETRIES
    late_reply_s: float = DEFAULT_LATE_REPLY_S

    @classmethod
    def checked(cls, timeout: object = None, retries: object = DEFAULT_RETRIES,
                late_reply_s: object = DEFAULT_LATE_REPLY_S) -> TransactionPolicy:
        """Options as a user gives them; ArgumentRangeError before anything is opened."""
        t = checks.optional_seconds("timeout", timeout)
        return cls(DEFAULT_TIMEOUT_S if t is None else t, checks.count("retries", retries),
                   checks.non_negative_seconds("late_reply_s", late_reply_s))

    def attempts(self, retry_safe: bool, retries: int | None = None) -> int:
        """How many times a command may be sent."""
        if not retry_safe:
            return 1
        return 1 + (self.retries if retries is None else checks.count("retries", retries))

    def deadline(self, timeout: float | None = None) -> float:
        return self.timeout if timeout is None else checks.seconds("timeout", timeout)
