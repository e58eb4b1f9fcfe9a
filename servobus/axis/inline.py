"""The sync facade on the caller's own thread, for a link that needs no loop between calls.

Decision (issue 22, the fast path for synchronous callers): a sync call over a link that
speaks only when asked - a DYN5 over EtherNet/IP, a DYN232M behind a serial-to-Ethernet
bridge: the schemes a protocol lists in its spec's ``inline_schemes`` - runs the same async
core on the calling thread. The call's coroutine becomes a task of a private asyncio loop,
and the call turns that loop (``_run_once``: wait on the sockets up to the next timer, run
what is ready) until the task is done. Between calls nothing runs, and nothing needs to:
what arrives meanwhile (a late reply) waits in the kernel and is read first by the next
call, by the same rules. So there is no thread hop per call, and no second transaction
path: deadlines, retries, late replies and checksums are the core's, as on the loop thread.
Measured (benchmarks/bench_enip.py, "servobus sync"): about 1.3x the reads/s of the loop
thread hop, on par with or above pycomm3.

The runner hands its loop to a :class:`~servobus.axis.sync.LoopThread` for good - the facade
then works exactly as without it - as soon as something needs the loop between calls or
from elsewhere: a task the core left running after a call (or callbacks still pending), a
call from a second thread, a call from a thread that runs an event loop of its own (a
notebook). A second thread never waits for a call in progress (a ``stop()`` during a long
``wait_idle``): that call lets go of the loop at once and finishes on the loop thread.
``timeout`` and Ctrl-C cancel the call's task and let it unwind by its own rules (its
reply, if it comes, is owed and dropped), as the loop thread does.

``_run_once`` is asyncio's per-pass method (``BaseEventLoop``, CPython 3.4 onwards), not a
public API: :func:`available` checks for it, and the loop thread is used where it is
missing, on Windows, and with ``SERVOBUS_SYNC=thread`` in the environment (to compare, or
to debug). The loop is asyncio's selector loop, not uvloop: no loop runs between calls, and
a call costs less than uvloop's thread hop.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
import threading
from asyncio import events
from collections.abc import Coroutine
from typing import Any, TypeVar

from servobus.axis.sync import LoopThread
from servobus.errors import ClosedError, DriveTimeout

T = TypeVar("T")

#: Environment variable: ``thread`` keeps every sync Axis on a loop thread.
ENV = "SERVOBUS_SYNC"
#: How long a cancelled call may take to unwind (its ``finally`` blocks) before the caller
#: gets its exception anyway; the task then finishes on the loop thread.
CANCEL_GRACE_S = 2.0
#: Passes run after a call while callbacks are still ready (a future's done callbacks).
_SETTLE_PASSES = 3
#: A call that finishes on the loop thread checks this often whether the runner was stopped.
_STOP_CHECK_S = 0.25


def available() -> bool:
    """The inline runner can run here (module docstring)."""
    return (sys.platform != "win32" and callable(getattr(asyncio.BaseEventLoop, "_run_once", None))
            and os.environ.get(ENV, "").strip().lower() != "thread")


def _noop() -> None:
    return None


class InlineRunner:
    """Runs each call on the calling thread until it hands the loop to a LoopThread."""

    def __init__(self, name: str = "servobus-loop") -> None:
        self.loop = asyncio.SelectorEventLoop()
        self.loop.set_task_factory(self._task)
        self._name = name
        self._spawned: list[asyncio.Task[Any]] = []  # tasks the core created
        self._lock = threading.Lock()  # held by the call in progress
        self._owner = threading.get_ident()  # the thread that may call inline
        self._thread: LoopThread | None = None
        self._wanted = False  # another thread waits for the loop: the owner lets go of it
        self._stopped = False

    @property
    def inline(self) -> bool:
        """Calls still run on the calling thread (False once handed to a loop thread)."""
        return self._thread is None and not self._stopped

    @property
    def stopped(self) -> bool:
        return self._stopped

    def _task(self, loop: asyncio.AbstractEventLoop, coro: Any,
              **kwargs: Any) -> asyncio.Task[Any]:
        task: asyncio.Task[Any] = asyncio.Task(coro, loop=loop, **kwargs)
        self._spawned.append(task)
        return task

    def run(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """Run ``coro`` to its result (exceptions propagate), on this thread while it can.

        ``timeout`` (a safety net: the core enforces the deadlines) raises TimeoutError after
        cancelling the coroutine, as :meth:`LoopThread.run` does.
        """
        thread = self._thread
        if thread is not None:
            return thread.run(coro, timeout)
        if self._stopped:
            coro.close()
            raise ClosedError("the connection is closed")
        running = events._get_running_loop()
        if running is self.loop:  # a hook or callback of this loop calling the facade
            coro.close()
            raise ClosedError("sync facade called from its own loop thread (use the async API)")
        if (running is not None or threading.get_ident() != self._owner
                or not self._lock.acquire(blocking=False)):
            return self._hand_over().run(coro, timeout)
        if self._thread is not None or self._stopped:  # handed over or stopped meanwhile
            self._lock.release()
            return self.run(coro, timeout)
        return self._drive(coro, timeout)  # releases the lock

    def _drive(self, coro: Coroutine[Any, Any, T], timeout: float | None) -> T:
        """The call on this thread, the lock held (released here: at the end, or as soon as
        another thread wants the loop - the call then finishes on the loop thread)."""
        loop = self.loop
        task: asyncio.Task[T] = asyncio.Task(coro, loop=loop)  # the call: not "spawned"
        end = None if timeout is None else loop.time() + timeout
        locked = True
        events._set_running_loop(loop)
        try:
            try:
                self._turn(task, end)
                if not task.done():
                    if end is not None and loop.time() >= end:
                        raise DriveTimeout(f"no result within {timeout} s")
                    # another thread calls (self._wanted): it must not wait for this call
                    self._start_thread()
                    events._set_running_loop(None)
                    self._lock.release()
                    locked = False
                    return self._finish(task, end, timeout)
            except BaseException:
                if locked:
                    # the timeout above, or Ctrl-C in the selector wait or in a callback:
                    # cancel the call's task and let it unwind by its own rules
                    task.cancel()
                    self._turn(task, loop.time() + CANCEL_GRACE_S, whole=True)
                    if task.done() and not task.cancelled():
                        task.exception()  # retrieved: asyncio logs no "never retrieved"
                    elif not task.done():
                        self._spawned.append(task)  # finishes on the loop thread
                raise
            self._settle()
        finally:
            if locked:
                events._set_running_loop(None)
                try:
                    if self._busy():
                        self._start_thread()
                finally:
                    self._lock.release()
        return task.result()

    def _turn(self, task: asyncio.Task[Any], end: float | None, *, whole: bool = False
              ) -> None:
        """Turn the loop until ``task`` is done, ``end`` (loop time) passed, or - unless
        ``whole`` - another thread wants the loop."""
        loop = self.loop
        if end is None and not whole:  # every call without a safety-net timeout
            while not task.done() and not self._wanted:
                loop._run_once()  # type: ignore[attr-defined]
            return
        guard = None if end is None else loop.call_at(end, _noop)  # bounds the selector wait
        try:
            while not task.done() and (whole or not self._wanted):
                if end is not None and loop.time() >= end:
                    return
                loop._run_once()  # type: ignore[attr-defined]
        finally:
            if guard is not None:
                guard.cancel()

    def _finish(self, task: asyncio.Task[T], end: float | None, timeout: float | None) -> T:
        """Wait for the call's task, now on the loop thread (a handover in mid-call)."""
        done = threading.Event()

        def watch() -> None:
            task.add_done_callback(lambda _task: done.set())

        self.loop.call_soon_threadsafe(watch)
        try:
            # in slices: a stop() meanwhile (the loop thread gone) must not leave this hanging
            while not done.wait(_STOP_CHECK_S if end is None
                                else min(_STOP_CHECK_S, max(0.0, end - self.loop.time()))):
                if self._stopped:
                    raise ClosedError("the connection was closed during the call")
                if end is not None and self.loop.time() >= end:
                    raise DriveTimeout(f"no result within {timeout} s")
        except BaseException:  # the timeout above, or Ctrl-C while waiting
            with contextlib.suppress(RuntimeError):
                self.loop.call_soon_threadsafe(task.cancel)
            raise
        return task.result()

    def _busy(self) -> bool:
        """Something needs the loop between calls: a task still running, or callbacks."""
        spawned = self._spawned
        if spawned:
            spawned[:] = [t for t in spawned if not t.done()]
        return bool(spawned) or bool(self.loop._ready)  # type: ignore[attr-defined]

    def _start_thread(self) -> LoopThread:
        """Hand the loop to a LoopThread, for good (with the lock held, or stopped)."""
        thread = self._thread
        if thread is None:
            self.loop.set_task_factory(None)
            self._spawned.clear()
            thread = self._thread = LoopThread(self._name, loop=self.loop)
        return thread

    def _settle(self) -> None:
        """Run the callbacks still ready after a call (a few passes at most)."""
        loop = self.loop
        n = 0
        while loop._ready and n < _SETTLE_PASSES:  # type: ignore[attr-defined]
            loop._run_once()  # type: ignore[attr-defined]
            n += 1

    def _take_lock(self) -> None:
        """Take the lock from another thread: a call in progress on the owner's thread is
        asked to let go of the loop (it finishes on the loop thread), not waited for."""
        if not self._lock.acquire(blocking=False):
            self._wanted = True
            with contextlib.suppress(RuntimeError):  # closed meanwhile: the caller says so
                self.loop.call_soon_threadsafe(_noop)  # wakes the owner's selector wait
            self._lock.acquire()

    def _hand_over(self) -> LoopThread:
        """From another thread, or a caller with a loop of its own: the loop goes to a loop
        thread now."""
        self._take_lock()
        try:
            if self._thread is None and self._stopped:
                raise ClosedError("the connection is closed")
            return self._start_thread()
        finally:
            self._lock.release()

    def stop(self) -> None:
        """Close the loop (stop the loop thread, if it has one); idempotent. A call in
        progress on the owner's thread lets go of the loop first, as for another thread."""
        if events._get_running_loop() is self.loop:
            raise ClosedError("sync facade stopped from its own loop thread (use the async API)")
        self._take_lock()
        try:
            if self._stopped:
                return
            self._stopped = True
            thread = self._thread
            if thread is not None:
                thread.stop()
                return
            loop = self.loop
            events._set_running_loop(loop)
            try:
                self._settle()
            finally:
                events._set_running_loop(None)
            loop.close()
        finally:
            self._lock.release()
