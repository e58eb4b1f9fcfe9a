"""The synchronous Axis: a private event loop on a daemon thread runs the async core.

The sync ``Axis`` submits each coroutine to this loop and blocks on the result, so the one
async core does all the work. Hooks registered through the facade run on the loop thread.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import inspect
import threading
from collections.abc import Coroutine
from types import TracebackType
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis

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


class Axis:
    """Synchronous facade over any AsyncAxis, derived from it rather than copied.

    Every coroutine method of the core (the Axis API and a protocol's extras such as
    synchronised moves) is available under the same name and runs on the facade's loop
    thread; plain attributes and properties are read through. ``sibling`` returns an Axis
    sharing the connection. Hooks registered through the facade run on the loop thread.
    """

    def __init__(self, core: AsyncAxis, runner: LoopThread, *, owns_runner: bool = True,
                 call_timeout: float | None = None) -> None:
        self._core = core
        self._runner = runner
        self._owns_runner = owns_runner
        self._call_timeout = call_timeout  # safety net only; the core enforces deadlines

    @property
    def core(self) -> AsyncAxis:
        """The async core (for use on the facade's loop thread only)."""
        return self._core

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        attr = getattr(self._core, name)
        if not inspect.iscoroutinefunction(attr):
            return attr

        @functools.wraps(attr)
        def call(*args: Any, **kwargs: Any) -> Any:
            return self._runner.run(attr(*args, **kwargs), self._call_timeout)

        return call

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | {n for n in dir(self._core)
                                                if not n.startswith("_")})

    def sibling(self, drive_id: int) -> Axis:
        core = self._runner.run(self._core.sibling(drive_id), self._call_timeout)
        return Axis(core, self._runner, owns_runner=False, call_timeout=self._call_timeout)

    def close(self) -> None:
        """Close the axis (the connection too unless this is a sibling); idempotent."""
        if self._runner.stopped:
            return
        try:
            self._runner.run(self._core.close(), self._call_timeout)
        finally:
            if self._owns_runner:
                self._runner.stop()

    def __enter__(self) -> Axis:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Axis {self._core.protocol} id {self._core.drive_id}>"
