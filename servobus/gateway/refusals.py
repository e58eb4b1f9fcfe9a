"""One log line per spell of refused commands, not one per command.

Any client the broker lets publish on ``.../cmd`` (or any OPC UA session) can send refused
commands as fast as the gateway answers them; a line each grew the log by 1.6 MB per 10,000
(``python -m benchmarks faults``). Decision: per source (``via`` and user), the first refusal
of a spell is logged in full; refusals in the next :data:`SPELL_S` seconds are counted, and the
first one after it is logged with how many were left out ("... and 9,999 more refused in
10 s"). Every refusal is still answered. At most :data:`MAX_SOURCES` sources are remembered
(the least recently seen is forgotten first), so a flood of user names cannot grow memory.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable

SPELL_S = 10.0
MAX_SOURCES = 256


class _Spell:
    __slots__ = ("quiet", "since")

    def __init__(self, since: float) -> None:
        self.since = since
        self.quiet = 0  # refusals counted, not logged, since ``since``


class RefusalLog:
    """:meth:`admit` says whether a refusal from ``source`` gets a log line, and what to add
    to it (the count left out since the last line)."""

    def __init__(self, spell_s: float = SPELL_S, max_sources: int = MAX_SOURCES,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.spell_s = spell_s
        self.max_sources = max_sources
        self._clock = clock
        self._spells: OrderedDict[str, _Spell] = OrderedDict()

    def __len__(self) -> int:
        return len(self._spells)

    def admit(self, source: str) -> str | None:
        """None: count it, log nothing. Otherwise log the refusal with this suffix ("" or
        "; and N more refused in S s")."""
        now = self._clock()
        spell = self._spells.get(source)
        if spell is not None and now - spell.since < self.spell_s:
            spell.quiet += 1
            self._spells.move_to_end(source)
            return None
        suffix = ""
        if spell is not None and spell.quiet:
            suffix = (f"; and {spell.quiet:,} more refused in the "
                      f"{now - spell.since:.0f} s before")
        self._spells[source] = _Spell(now)
        self._spells.move_to_end(source)
        while len(self._spells) > self.max_sources:
            self._spells.popitem(last=False)
        return suffix
