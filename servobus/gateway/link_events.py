"""Link events: one when a link goes down, one when it is back (issue 29).

The machine reopens a dropped link by itself (docs/machine.md "Recovery") and logs one line
when it goes down and one when it is back. The gateway tells its clients the same two
things: after each sampling round the :class:`LinkWatch` compares the link's axes with the
last round and gives a :class:`LinkEvent` on a change, never one per reconnect try (the
tries are the machine's, between two rounds the state has not changed). It logs nothing of
its own: the machine's line is the event's one line.

Decisions (docs/gateway.md "Recovery"):

* a link is *down* from the moment its axes are offline until they are online again and
  the machine has checked them for a power loss (``checking``): the "back" event says
  which axes the drives flagged (``power_lost``), so a client learns in one message
  whether it must acknowledge before it moves them;
* a link that dropped and came back between two rounds (a fast reconnect) still gives both
  events: the machine gave its axes new Axis objects, which the watch notices;
* a link's first state (at the gateway's start) is no event: a link offline at start is
  in the values' status and the machine's start-up line; its first opening is "back".
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from servobus.gateway.source import MachineAxis

log = logging.getLogger(__name__)

#: The "down" reason when a link was reopened before a round saw it offline.
REOPENED = "the link dropped and was reopened"


@dataclass(frozen=True)
class LinkEvent:
    """A link (one URL of the machine) went down (``online`` False) or came back."""

    url: str
    axes: tuple[str, ...]
    online: bool
    time: float
    reason: str = ""  # down: why (the machine's error)
    last_good: float | None = None  # the newest last good call of its axes
    power_lost: tuple[str, ...] = ()  # back: axes flagged, to acknowledge before motion
    interrupted: tuple[str, ...] = ()  # axes whose motion the drop interrupted (not re-sent)

    @property
    def message(self) -> str:
        """One human line (the OPC UA event's Message)."""
        names = ", ".join(self.axes)
        if not self.online:
            return f"link {self.url} (axes {names}) is down: {self.reason}"
        text = f"link {self.url} (axes {names}) is back"
        if self.power_lost:
            text += (f"; the drive of {', '.join(self.power_lost)} may have lost power: "
                     "acknowledge before the next motion")
        return text


LinkListener = Callable[[LinkEvent], None]


class LinkWatch:
    """The last state seen of each link; :meth:`observe` gives the events of a change."""

    def __init__(self) -> None:
        self._up: dict[str, bool] = {}
        self._cores: dict[str, tuple[object, ...]] = {}

    def observe(self, url: str, axes: Sequence[MachineAxis]) -> list[LinkEvent]:
        """The link's state now (read from its axes at once, no await between) against
        the last one: no event, "down", "back", or both (reopened between two rounds)."""
        up = all(a.online and not a.checking for a in axes)
        cores = tuple(a.axis for a in axes)
        before, old = self._up.get(url), self._cores.get(url, ())
        self._up[url], self._cores[url] = up, cores
        if before is None:
            return []
        replaced = up and before and any(a is not b for a, b in zip(cores, old, strict=False))
        events = []
        if before and (not up or replaced):
            events.append(_event(url, axes, False))
        if up and (not before or replaced):
            events.append(_event(url, axes, True))
        for event in events:
            log.debug("%s", event.message)
        return events


def _event(url: str, axes: Sequence[MachineAxis], online: bool) -> LinkEvent:
    errors = [a.last_error for a in axes if a.last_error is not None]
    reason = "" if online else str(errors[0]) if errors else REOPENED
    goods = [a.last_good for a in axes if a.last_good is not None]
    return LinkEvent(url, tuple(a.name for a in axes), online, time.time(), reason,
                     max(goods) if goods else None,
                     tuple(a.name for a in axes if a.power_lost),
                     tuple(a.name for a in axes if a.interrupted is not None))
