"""Decoded traffic of a connection (what ``servobus sniff`` shows) for the Diagnostics panel.

The hook (``axis.add_trace``) only stores what it is given; formatting happens when the page
asks, so a busy link costs a deque append per packet. Items are the protocol's decoded
packets or frames (their ``describe(from_drive)`` gives the text, as in sniff), error
events, or the exceptions the client met.
"""

from __future__ import annotations

import itertools
import time
from collections import deque
from dataclasses import dataclass

from servobus.transport.base import Direction

KEEP = 2000


@dataclass(frozen=True)
class Entry:
    seq: int
    t: float  # time.monotonic()
    direction: Direction
    item: object


def describe(item: object, direction: Direction) -> tuple[str, bool]:
    """(text, is_error) of one traced item."""
    if isinstance(item, BaseException):
        return f"{type(item).__name__}: {item}", True
    is_error = bool(getattr(item, "is_error", False))
    describe_fn = getattr(item, "describe", None)
    if callable(describe_fn):
        try:
            return str(describe_fn(direction is Direction.RX)), is_error
        except TypeError:
            pass
    lines = getattr(item, "lines", None)
    if callable(lines):
        return " ".join(str(x).strip() for x in lines()), is_error
    return repr(item), is_error


class TrafficLog:
    def __init__(self, keep: int = KEEP) -> None:
        self.entries: deque[Entry] = deque(maxlen=keep)
        self.counts = {"tx": 0, "rx": 0, "errors": 0}
        self._seq = itertools.count(1)
        self.t0 = time.monotonic()

    def hook(self, direction: Direction, item: object, t: float) -> None:
        self.entries.append(Entry(next(self._seq), t, direction, item))
        self.counts[direction.value] += 1
        if isinstance(item, BaseException) or getattr(item, "is_error", False):
            self.counts["errors"] += 1

    def recent(self, limit: int = 200, after: int = 0) -> list[dict[str, object]]:
        """The newest ``limit`` entries with seq > ``after``, oldest first."""
        picked = [e for e in list(self.entries)[-limit:] if e.seq > after]
        out: list[dict[str, object]] = []
        for e in picked:
            text, error = describe(e.item, e.direction)
            out.append({"seq": e.seq, "t": e.t - self.t0, "dir": e.direction.value,
                        "text": text, "error": error})
        return out
