"""Link statistics the GUI can know as an Axis client: calls, failures, round-trip times.

Every call the GUI makes on an axis goes through :meth:`CallStats.timed`, so the
Diagnostics panel shows round trips, timeouts and errors per axis whatever the protocol.
Retries happen inside the protocol client; where the client counts its own transactions
(``Capability.LINK_STATS``: every link client), they are shown too, asked of the Axis by
capability (the GUI imports no protocol).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Awaitable
from dataclasses import dataclass, field
from typing import TypeVar

from servobus.axis.base import AsyncAxis
from servobus.axis.capabilities import Capability
from servobus.errors import ConnectionLost, DriveTimeout

T = TypeVar("T")


@dataclass
class CallStats:
    calls: int = 0
    errors: int = 0
    timeouts: int = 0
    total_s: float = 0.0
    max_s: float = 0.0
    last_s: float = 0.0
    last_error: str = ""
    last_error_at: float = 0.0  # time.time()
    started: float = field(default_factory=time.monotonic)

    async def timed(self, awaitable: Awaitable[T]) -> T:
        t0 = time.monotonic()
        try:
            result = await awaitable
        except DriveTimeout as exc:
            self.timeouts += 1
            self._failed(exc)
            raise
        except (ConnectionLost, OSError, ValueError, RuntimeError) as exc:
            self.errors += 1
            self._failed(exc)
            raise
        finally:
            dt = time.monotonic() - t0
            self.calls += 1
            self.total_s += dt
            self.last_s = dt
            self.max_s = max(self.max_s, dt)
        return result

    def _failed(self, exc: BaseException) -> None:
        self.last_error = f"{type(exc).__name__}: {exc}"
        self.last_error_at = time.time()

    def as_dict(self) -> dict[str, object]:
        elapsed = max(1e-9, time.monotonic() - self.started)
        return {
            "calls": self.calls, "errors": self.errors, "timeouts": self.timeouts,
            "calls_per_s": self.calls / elapsed,
            "mean_ms": 1000 * self.total_s / self.calls if self.calls else None,
            "max_ms": 1000 * self.max_s, "last_ms": 1000 * self.last_s,
            "last_error": self.last_error, "last_error_at": self.last_error_at or None,
        }


def client_counters(axis: AsyncAxis) -> dict[str, object] | None:
    """The protocol client's own counters (Capability.LINK_STATS), else None."""
    if not axis.supports(Capability.LINK_STATS):
        return None
    return {k: v for k, v in dataclasses.asdict(axis.link_stats()).items()
            if isinstance(v, int | float | str)}
