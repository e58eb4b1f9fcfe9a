"""Decoded traffic of a connection (what ``servobus sniff`` shows) for the Diagnostics panel:
one line per transaction, in the protocol's sniff decoder's words (each traced item's
``describe``), never a Python repr.

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
#: How long the newest request waits for its reply before it is shown alone.
REPLY_WAIT_S = 0.3


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
    return f"{type(item).__name__}: not decoded", is_error  # never a repr (issue 33)


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

    def recent(self, limit: int = 200, after: int = 0,
               now: float | None = None) -> list[dict[str, object]]:
        """The newest ``limit`` entries with seq > ``after``, oldest first, one line per
        transaction (issue 33): a reply right after its request joins the request's line
        (``dir`` "pair", ``text`` "request => reply"). A request that is the newest entry
        and younger than :data:`REPLY_WAIT_S` waits for its reply (the next call gets it,
        its seq being above the last one returned)."""
        picked = [e for e in list(self.entries)[-limit:] if e.seq > after]
        now = time.monotonic() if now is None else now
        out: list[dict[str, object]] = []
        last: Entry | None = None
        for e in picked:
            text, error = describe(e.item, e.direction)
            head = out[-1] if out else None
            if (head is not None and last is not None and e.direction is Direction.RX
                    and last.direction is Direction.TX and last.seq == e.seq - 1
                    and head["dir"] == "tx" and not head["error"]):
                head.update({"seq": e.seq, "dir": "pair", "error": error,
                             "text": f"{head['text']}  =>  {text}"})
            else:
                out.append({"seq": e.seq, "t": e.t - self.t0, "dir": e.direction.value,
                            "text": text, "error": error})
            last = e
        if (out and last is not None and out[-1]["dir"] == "tx"
                and now - last.t < REPLY_WAIT_S):
            out.pop()
        return out
