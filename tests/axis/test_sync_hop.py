"""The sync facade's runners (issue 22): the hop to a loop thread (a bare lock per call, not
a concurrent Future) and the inline runner (the call on the caller's own thread) give the
same results and errors, and a give-up that cancels the coroutine on the loop."""

from __future__ import annotations

import asyncio
import threading

import pytest

from servobus.axis.inline import InlineRunner
from servobus.axis.sync import LoopThread, Runner
from servobus.errors import DriveTimeout


@pytest.fixture(params=["thread", "inline"])
def runner(request: pytest.FixtureRequest):  # type: ignore[no-untyped-def]
    r = LoopThread() if request.param == "thread" else InlineRunner()
    yield r
    r.stop()


def test_result_and_error_cross_the_hop(runner: Runner) -> None:
    async def answer() -> int:
        return 42

    async def fail() -> None:
        raise DriveTimeout("no reply")

    assert runner.run(answer()) == 42
    with pytest.raises(DriveTimeout, match="no reply"):
        runner.run(fail())


def test_timeout_cancels_the_coroutine_on_the_loop(runner: Runner) -> None:
    cancelled = threading.Event()
    started = threading.Event()

    async def hang() -> None:
        started.set()
        try:
            await asyncio.Event().wait()
        except asyncio.CancelledError:
            cancelled.set()
            raise

    with pytest.raises(DriveTimeout):  # typed (servobus.errors), still a TimeoutError
        runner.run(hang(), timeout=0.2)
    assert started.is_set()
    assert cancelled.wait(5.0)

    async def after() -> str:
        return "next call runs"

    assert runner.run(after()) == "next call runs"


def test_refused_from_its_own_loop_thread(runner: Runner) -> None:
    async def inner() -> None:
        return None

    async def outer() -> str:
        coro = inner()
        try:
            runner.run(coro)
        except RuntimeError as exc:
            return str(exc)
        return "ran"

    assert "own loop thread" in runner.run(outer())


def test_closed_runner_refuses(runner: Runner) -> None:
    runner.stop()

    async def nothing() -> None:
        return None

    with pytest.raises(RuntimeError, match="closed"):
        runner.run(nothing())
