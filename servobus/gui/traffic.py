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
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from servobus.transport.base import Direction

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis

KEEP = 2000
#: How long the newest request waits for its reply before it is shown alone.
REPLY_WAIT_S = 0.3


#: An Axis's ``describe_traced``: a traced item in its protocol's words, or None.
Words = Callable[[object, bool], "str | None"]


@dataclass(frozen=True)
class Entry:
    seq: int
    t: float  # time.monotonic()
    direction: Direction
    item: object
    words: Words | None = None  # the tracing Axis's describe_traced


def describe(item: object, direction: Direction,
             words: Words | None = None) -> tuple[str, bool]:
    """(text, is_error) of one traced item: the tracing Axis's words for it (``words``),
    else the item's own ``describe``/``lines``."""
    if isinstance(item, BaseException):
        return f"{type(item).__name__}: {item}", True
    is_error = bool(getattr(item, "is_error", False))
    if words is not None:
        text = words(item, direction is Direction.RX)
        if text is not None:
            return text, is_error
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

    def hook_for(self, axis: AsyncAxis) -> Callable[[Direction, object, float], None]:
        """The trace hook for ``axis``'s link: its items are described by the Axis
        (``describe_traced``, formatted only when a page asks)."""
        words = axis.describe_traced

        def hook(direction: Direction, item: object, t: float) -> None:
            self.hook(direction, item, t, words)

        return hook

    def hook(self, direction: Direction, item: object, t: float,
             words: Words | None = None) -> None:
        self.entries.append(Entry(next(self._seq), t, direction, item, words))
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
            text, error = describe(e.item, e.direction, e.words)
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
