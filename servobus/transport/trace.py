"""Trace helpers: record, count and format what transports and clients report.

Two levels share the same hook shape ``hook(direction, item, t)``:

* transports (``ByteStream.add_trace``) report raw byte chunks;
* clients (``AsyncAxis.add_trace``) report decoded items: codec packets and the
  ProtocolError/DriveTimeout events met while waiting for a reply.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TextIO

from servobus.transport.base import Direction

#: Client-level hook: item is a decoded packet, or an exception describing a failure.
ItemHook = Callable[[Direction, object, float], None]


@dataclass(frozen=True)
class TraceEvent:
    direction: Direction
    item: object
    t: float


@dataclass
class TraceRecorder:
    """Collects every event; usable as a byte-level or item-level hook."""

    events: list[TraceEvent] = field(default_factory=list)

    def __call__(self, direction: Direction, item: object, t: float) -> None:
        self.events.append(TraceEvent(direction, item, t))

    def items(self, direction: Direction | None = None) -> list[object]:
        return [e.item for e in self.events if direction is None or e.direction is direction]

    def of_type(self, cls: type) -> list[object]:
        return [e.item for e in self.events if isinstance(e.item, cls)]

    def clear(self) -> None:
        self.events.clear()


@dataclass
class ByteCounter:
    """Counts bytes per direction from a byte-level (transport) trace."""

    tx: int = 0
    rx: int = 0

    def __call__(self, direction: Direction, item: object, t: float) -> None:
        if isinstance(item, bytes | bytearray):
            if direction is Direction.TX:
                self.tx += len(item)
            else:
                self.rx += len(item)


def format_event(direction: Direction, item: object, t: float | None = None,
                 t0: float = 0.0) -> str:
    """One human-readable line: time, arrow, then hex bytes or the item's description."""
    arrow = "->" if direction is Direction.TX else "<-"
    stamp = "" if t is None else f"{(t - t0) * 1000:10.3f} ms "
    if isinstance(item, bytes | bytearray):
        text = bytes(item).hex(" ")
    elif isinstance(item, BaseException):
        text = f"!! {type(item).__name__}: {item}"
    else:
        text = describe_item(direction, item)
    return f"{stamp}{arrow} {text}"


def describe_item(direction: Direction, item: object) -> str:
    """Decoded items describe themselves (``item.describe(from_drive)``); else repr.

    The transport knows no protocol: every codec's packet/frame type has ``describe``.
    """
    describe = getattr(item, "describe", None)
    if callable(describe):
        return str(describe(direction is Direction.RX))
    return repr(item)


def printer(stream: TextIO | None = None) -> Callable[[Direction, object, float], None]:
    """A hook that prints every event with milliseconds since the first one."""
    import sys

    out = stream if stream is not None else sys.stderr
    t0 = [time.monotonic()]

    def hook(direction: Direction, item: object, t: float) -> None:
        print(format_event(direction, item, t, t0[0]), file=out)

    return hook
