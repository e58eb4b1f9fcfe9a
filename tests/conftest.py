"""Shared test helpers: async tests without a plugin, and waiting on a condition.

* ``async def test_...`` functions run on a fresh event loop each (no pytest-asyncio needed).
* ``wait_until(predicate, timeout=..., poll=...)`` polls until ``predicate()`` is true and
  fails the test with the last value when ``timeout`` passes - for conditions that have no
  event to wait on (simulated physics in wall-clock time). ``await wait_until_async(...)``
  does the same for coroutine predicates.
"""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import Awaitable, Callable
from typing import Any

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    """Run ``async def`` tests with asyncio.run (fixtures are passed as keyword arguments)."""
    if not inspect.iscoroutinefunction(pyfuncitem.obj):
        return None
    names = pyfuncitem._fixtureinfo.argnames
    kwargs = {name: pyfuncitem.funcargs[name] for name in names}
    asyncio.run(pyfuncitem.obj(**kwargs))
    return True


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
