"""EEPROM guard: count parameter/config/id writes; warn on tight loops, refuse past a rate.

The manual (section 7): "Never use serial communication to set the Drive configuration or
parameters at a fast rate ... The guaranteed parameter writing cycle for EEPROM is 1 million
times." A host loop writing one parameter at full line speed (~480 packets/s at 38400 baud)
would use up those cycles in about 35 minutes.

Defaults (servobus decisions; the manual gives only the lifetime figure):

* window 60 s, counted per drive and per item (parameter name, "config", "drive_id");
* more than ``warn_per_window`` = 10 writes of one item in the window -> EepromWearWarning;
* more than ``max_per_window`` = 30 writes of one item in the window -> EepromGuardError,
  raised before anything is sent. A restore of all parameters writes each item once, so it
  is never affected; only loops are.
* also per drive: more than ``max_drive_per_window`` = 200 writes of any items -> refused.

At the refusal limit sustained forever an item reaches 1,000,000 cycles after ~23 days: the
guard stops accidents (loops), not deliberate wear; lifetime counts are in ``totals``.
``EepromGuard.disabled()`` turns it off (e.g. factory programming jigs).
"""

from __future__ import annotations

import logging
import time
import warnings
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from servobus.errors import EepromGuardError

EEPROM_CYCLE_LIMIT = 1_000_000  # manual section 7

log = logging.getLogger(__name__)


class EepromWearWarning(UserWarning):
    """EEPROM-backed settings are being written in a loop."""


@dataclass
class EepromGuard:
    warn_per_window: int = 10
    max_per_window: int = 30
    max_drive_per_window: int = 200
    window_s: float = 60.0
    enabled: bool = True
    clock: Callable[[], float] = time.monotonic
    totals: dict[tuple[int, str], int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._recent: dict[tuple[int, str], deque[float]] = {}
        self._drive_recent: dict[int, deque[float]] = {}

    @classmethod
    def disabled(cls) -> EepromGuard:
        return cls(enabled=False)

    def _trim(self, q: deque[float], now: float) -> deque[float]:
        while q and q[0] <= now - self.window_s:
            q.popleft()
        return q

    def check(self, drive_id: int, item: str) -> None:
        """Call before sending one EEPROM write; raises EepromGuardError or warns, then counts."""
        now = self.clock()
        key = (drive_id, item)
        recent = self._trim(self._recent.setdefault(key, deque()), now)
        drive = self._trim(self._drive_recent.setdefault(drive_id, deque()), now)
        if self.enabled:
            if len(recent) >= self.max_per_window:
                raise EepromGuardError(
                    f"refused: {item} of drive {drive_id} was written {len(recent)} times in "
                    f"the last {self.window_s:g} s (limit {self.max_per_window}); the drive's "
                    f"EEPROM is rated for {EEPROM_CYCLE_LIMIT:,} write cycles. Nothing was sent."
                )
            if len(drive) >= self.max_drive_per_window:
                raise EepromGuardError(
                    f"refused: drive {drive_id} had {len(drive)} EEPROM writes in the last "
                    f"{self.window_s:g} s (limit {self.max_drive_per_window}). Nothing was sent."
                )
            if len(recent) >= self.warn_per_window:
                text = (f"{item} of drive {drive_id} written {len(recent) + 1} times in "
                        f"{self.window_s:g} s: EEPROM wears out after "
                        f"{EEPROM_CYCLE_LIMIT:,} cycles")
                log.warning("%s", text)
                warnings.warn(text, EepromWearWarning, stacklevel=3)
        recent.append(now)
        drive.append(now)
        self.totals[key] = self.totals.get(key, 0) + 1

    def writes(self, drive_id: int, item: str | None = None) -> int:
        """Lifetime writes sent through this guard (per item, or all items of a drive)."""
        if item is not None:
            return self.totals.get((drive_id, item), 0)
        return sum(n for (d, _), n in self.totals.items() if d == drive_id)

    def rename_drive(self, old_id: int, new_id: int) -> None:
        """After Assign_Drive_ID the same EEPROM answers to another id: keep its history."""
        if old_id == new_id:
            return
        for (d, item) in list(self._recent):
            if d == old_id:
                self._recent[(new_id, item)] = self._recent.pop((old_id, item))
        for (d, item) in list(self.totals):
            if d == old_id:
                self.totals[(new_id, item)] = (self.totals.pop((old_id, item))
                                               + self.totals.get((new_id, item), 0))
        if old_id in self._drive_recent:
            self._drive_recent[new_id] = self._drive_recent.pop(old_id)
