"""Ending an MQTT session's tasks when a cancellation may have been swallowed on the way.

Python 3.11's ``asyncio.wait_for`` returns the awaited result instead of raising
CancelledError when the cancellation and that result arrive in the same loop iteration
(fixed in 3.12). aiomqtt waits for every QoS 1 publish, its connect and its subscribe with
it. A task cancelled just as its publish was acknowledged runs on, its cancellation
consumed. Seen (issue: the Sparkplug broker-restart test hung until its 120 s timeout, on a
loaded host): ``Gateway.close`` waited for ever on the MQTT session, whose publish loop was
back in its sleep, "cancelling", after one ``cancel()``.

Decisions:

* :func:`cancel_until_ended` cancels again every :data:`CANCEL_AGAIN_S` until each task has
  ended. Only for tasks without an awaited cleanup of their own (a session's loops): a
  repeated cancel would cut such a cleanup short.
* :func:`check_not_cancelled` raises CancelledError where a cancellation was swallowed
  (``Task.cancelling()`` is still counted: nothing handled it), so that a session does not
  start after its connect swallowed the gateway's stop.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Any

#: How long a cancelled task gets to end before it is cancelled again.
CANCEL_AGAIN_S = 0.05


async def cancel_until_ended(tasks: Iterable[asyncio.Task[Any]]) -> None:
    """Cancel ``tasks`` until every one has ended (module docstring); their exceptions are
    retrieved, not raised."""
    every = list(tasks)
    pending = set(every)
    while pending:
        for task in pending:
            task.cancel()
        _, pending = await asyncio.wait(pending, timeout=CANCEL_AGAIN_S)
    for task in every:
        if not task.cancelled():
            task.exception()  # retrieved: asyncio logs no "never retrieved"


def check_not_cancelled() -> None:
    """CancelledError when the running task was cancelled and the cancellation was
    swallowed below it (module docstring)."""
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError
