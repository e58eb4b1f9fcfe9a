"""``<name>.watchdog``: the bit LinuxCNC toggles to say it still feeds the component
(docs/linuxcnc.md, "position")."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from servobus.hal.pins import Pins

log = logging.getLogger(__name__)

Clock = Callable[[], float]


class Watchdog:
    """``<name>.watchdog``: starved when it has not toggled for ``timeout_s``.

    Decision: until its first toggle it counts as starved (every axis shows ``fault``, no
    position axis streams) without tripping: LinuxCNC starts its threads after loading the
    component, so a trip there would only ask for a fault-reset at every start. Once fed,
    a gap longer than ``timeout_s`` trips (:meth:`poll` returns True once): every position
    axis stops and every axis latches a fault until fault-reset."""

    def __init__(self, pins: Pins, timeout_s: float, clock: Clock = time.monotonic) -> None:
        self.pins = pins
        self.timeout_s = timeout_s
        self._clock = clock
        self._value = bool(pins["watchdog"])
        self._changed = clock()
        self.fed = False  # toggled at least once
        self.starved = True

    def poll(self) -> bool:
        """True when it starved just now (a toggle ends the starving)."""
        value = bool(self.pins["watchdog"])
        now = self._clock()
        if value != self._value:
            self._value = value
            self._changed = now
            if self.starved:
                log.warning("watchdog: toggling%s", " again" if self.fed else "")
            self.fed = True
            self.starved = False
            return False
        if self.fed and not self.starved and now - self._changed > self.timeout_s:
            self.starved = True
            log.warning("watchdog: no toggle for %g s: every position axis stops",
                        self.timeout_s)
            return True
        return False
