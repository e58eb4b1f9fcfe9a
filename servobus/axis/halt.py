"""Stop every axis first: the one helper every owner of axes calls when it shuts down.

The GUI, the machine and the gateway all hold axes that can be turning when they go away
(Ctrl-C, SIGTERM, an exception in any of their tasks). Each of them calls :func:`halt`
before it stops anything else, so that no other failure can skip the stop.

Decision: all axes are told to stop at once (a stop does not wait for another axis's
link), each bounded by its own deadline; a failure on one axis is logged in one line and
returned, never raised, so the others are still stopped and the caller's own shutdown goes on.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import TypeVar

from servobus.axis.base import AsyncAxis

log = logging.getLogger(__name__)

K = TypeVar("K")
DEFAULT_HALT_TIMEOUT_S = 2.0


async def _stop_one(axis: AsyncAxis, timeout_s: float) -> None:
    await asyncio.wait_for(axis.stop(), timeout_s)


async def halt(axes: Mapping[K, AsyncAxis], *, timeout_s: float = DEFAULT_HALT_TIMEOUT_S,
               stop: Callable[[AsyncAxis, float], Awaitable[None]] = _stop_one,
               ) -> dict[K, BaseException | None]:
    """Stop every axis at once; ``None`` per axis that stopped, else what went wrong.

    Never raises for an axis (timeouts and drive errors included) and shields the stops
    from the caller's cancellation: a shutdown cancelled half-way still stops every motor.
    ``stop`` replaces how one axis is stopped (e.g. through a caller's call counter).
    """
    keys = list(axes)
    gathered = asyncio.gather(*(stop(axes[k], timeout_s) for k in keys),
                              return_exceptions=True)
    try:
        results = await asyncio.shield(gathered)
    except asyncio.CancelledError:
        _outcome(keys, await gathered)  # the stops finish (and are logged) before we go
        raise
    return _outcome(keys, results)


def _outcome(keys: list[K], results: Sequence[object]) -> dict[K, BaseException | None]:
    out: dict[K, BaseException | None] = {}
    for key, result in zip(keys, results, strict=True):
        if isinstance(result, BaseException):
            if isinstance(result, TimeoutError):
                result = TimeoutError("did not confirm the stop in time")
            log.error("stop of axis %s failed: %s: %s", key, type(result).__name__, result)
            out[key] = result
        else:
            out[key] = None
    return out
