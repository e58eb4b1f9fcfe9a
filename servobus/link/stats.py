"""The counters every link keeps, the same fields on every protocol.

:class:`TransactionStats` counts one link's transactions (all drives on it; the
:class:`~servobus.link.transaction.TransactionManager` keeps them). :class:`StreamStats`
counts one cyclic stream of set-points (DYN CAN Position Direct, EasyCan synchronised
motion).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class TransactionStats:
    """Counters of one link (all drives on it); the same fields on every protocol."""

    sent: int = 0  # requests and commands handed to the medium
    replies: int = 0  # replies returned to a caller
    retries: int = 0  # re-sent reads
    timeouts: int = 0  # attempts that got no reply within their deadline
    checksum_errors: int = 0  # corrupt replies (never parsed)
    framing_errors: int = 0  # truncated packets, garbage, malformed frames
    unmatched: int = 0  # well-formed replies nobody waited for (and not owed)
    late_replies: int = 0  # replies owed to timed-out attempts, dropped
    error_replies: int = 0  # replies reporting an error (DYN CAN 0xFF, Modbus exception)
    alarms: int = 0  # alarms the drives pushed unasked (DYN CAN 0xEE)


@dataclass
class StreamStats:
    """Counters of one stream of cyclic set-points."""

    cycles: int = 0  # cycles sent
    frames: int = 0
    late_cycles: int = 0  # cycles sent more than one period after their slot, still sent
    skipped: int = 0  # cycles dropped because the host was more than a cycle behind
    max_lateness_s: float = 0.0
    elapsed_s: float = 0.0
