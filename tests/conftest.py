"""Shared test helpers: waiting on a condition, and the session-end check for leftovers.

* ``async def test_...`` functions run on a fresh event loop each, by pytest-asyncio in auto
  mode (pyproject ``asyncio_mode = "auto"``): no marker, no decorator.
* ``wait_until(predicate, timeout=..., poll=...)`` polls until ``predicate()`` is true and
  fails the test with the last value when ``timeout`` passes - for conditions that have no
  event to wait on (simulated physics in wall-clock time). ``await wait_until_async(...)``
  does the same for coroutine predicates.
"""

from __future__ import annotations

import asyncio
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
        time.sleep(poll)


async def wait_until_async(predicate: Callable[[], Awaitable[Any]], *, timeout: float = 5.0,
                           poll: float = 0.01, what: str = "condition") -> Any:
    """``wait_until`` for a coroutine predicate, without blocking the event loop."""
    deadline = time.monotonic() + timeout
    while True:
        value = await predicate()
        if value:
            return value
        if time.monotonic() >= deadline:
            pytest.fail(f"{what} not met within {timeout:g} s (last: {value!r})")
        await asyncio.sleep(poll)
