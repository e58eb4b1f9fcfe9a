"""A private event loop on a daemon thread, for the synchronous facades.

The sync ``Axis`` submits each coroutine to this loop and blocks on the result, so the one
async core does all the work. Hooks registered through the facade run on the loop thread.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class LoopThread:
    """Owns an asyncio loop running on its own daemon thread until :meth:`stop`."""

    def __init__(self, name: str = "servobus-loop") -> None:
        self.loop = asyncio.new_event_loop()
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        self._started.wait()
        self._stopped = False

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.call_soon(self._started.set)
        self.loop.run_forever()

    def run(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """Run ``coro`` on the loop and wait for its result (exceptions propagate)."""
        if self._stopped:
            coro.close()
            raise RuntimeError("the connection is closed")
        if threading.current_thread() is self._thread:
            coro.close()
            raise RuntimeError("sync facade called from its own loop thread (use the async API)")
        future = asyncio.run_coroutine_threadsafe(coro, self.loop)
        try:
            return future.result(timeout)
        except (KeyboardInterrupt, concurrent.futures.TimeoutError):
            future.cancel()
            raise

    def stop(self) -> None:
        """Stop the loop and join the thread; idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(5.0)
        if not self.loop.is_running():
            self.loop.close()

    @property
    def stopped(self) -> bool:
        return self._stopped
