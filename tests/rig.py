"""The helpers any test may import: waiting on a condition, and a free loopback port.

* ``wait_until(predicate, timeout=..., poll=...)`` polls until ``predicate()`` is true and
  fails the test with the last value when ``timeout`` passes - for conditions that have no
  event to wait on (simulated physics in wall-clock time). ``await wait_until_async(...)``
  does the same for coroutine predicates.
* ``free_port()`` is a TCP port on 127.0.0.1 that nothing listens on (bound once, then
  released), for a server a test starts as a separate process, or for "nothing there".

A module of its own, not ``conftest``: pytest loads conftest.py itself, as a plugin, and it
holds only fixtures and hooks; importing it by name again made a second copy of it, and any
conftest.py in a test folder would have shadowed it (docs/testing.md).
Rigs for one area sit beside it (subprocess_rig, can_rig, ...) or in the area's folder.
"""

from __future__ import annotations

import asyncio
import inspect
import socket
import time
from collections.abc import Awaitable, Callable
from typing import Any

import pytest


def wait_until(predicate: Callable[[], Any], *, timeout: float = 5.0,
               poll: float = 0.01, what: str = "condition") -> Any:
    """Poll ``predicate`` until it returns something true; return it, or fail on timeout."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() >= deadline:
            pytest.fail(f"{what} not met within {timeout:g} s (last: {value!r})")
        time.sleep(poll)  # the polling helper's own short sleep


async def wait_until_async(predicate: Callable[[], Awaitable[Any] | Any], *,
                           timeout: float = 5.0, poll: float = 0.01,
                           what: str = "condition") -> Any:
    """``wait_until`` inside a running loop, without blocking it; ``predicate`` may be a
    coroutine function or a plain one (a state that tasks on the loop change)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if inspect.isawaitable(value):
            value = await value
        if value:
            return value
        if time.monotonic() >= deadline:
            pytest.fail(f"{what} not met within {timeout:g} s (last: {value!r})")
        await asyncio.sleep(poll)  # the polling helper's own short sleep


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on (bound once, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
