"""The inline runner (issue 22): a sync call on the caller's own thread, and the hand-over of
its loop to a loop thread, for good, as soon as something needs the loop between calls or
from elsewhere. tests/axis/test_sync_hop.py holds what it shares with the loop thread."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator

import pytest

from servobus.axis import inline
from servobus.axis.inline import InlineRunner
from servobus.errors import DriveTimeout

pytestmark = pytest.mark.timeout(60)
WAIT_S = 10.0  # generous: only a hang or a lost hand-over reaches it


@pytest.fixture
def runner() -> Iterator[InlineRunner]:
    r = InlineRunner()
    yield r
    r.stop()


async def _here() -> int:
    return threading.get_ident()


def test_a_call_runs_on_the_calling_thread_and_starts_none(runner: InlineRunner) -> None:
    threads = threading.active_count()
    for _ in range(3):
        assert runner.run(_here()) == threading.get_ident()
    assert runner.inline and threading.active_count() == threads


def test_timers_and_sockets_are_served_during_a_call(runner: InlineRunner) -> None:
    async def round_trip() -> bytes:
        server = await asyncio.start_server(_echo, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        try:
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            writer.write(b"ping")
            await asyncio.sleep(0.01)  # a timer of the call's own (what a deadline is)
            data = await reader.readexactly(4)
            writer.close()
            await writer.wait_closed()
            return data
        finally:
            server.close()
            await server.wait_closed()

    assert runner.run(round_trip()) == b"ping"
    assert runner.inline


async def _echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    writer.write(await reader.readexactly(4))
    await writer.drain()
    writer.close()


def test_a_task_left_running_hands_the_loop_over(runner: InlineRunner) -> None:
    """Background work the core starts goes on between calls, without another call."""
    done = threading.Event()
    go: list[asyncio.Event] = []

    async def background() -> None:
        await go[0].wait()
        done.set()

    async def start() -> None:
        go.append(asyncio.Event())
        asyncio.get_running_loop().create_task(background())

    runner.run(start())
    assert not runner.inline
    runner.loop.call_soon_threadsafe(go[0].set)  # runs only if a thread turns the loop now
    assert done.wait(WAIT_S)
    assert runner.run(_here()) != threading.get_ident()  # on the loop thread now


def test_a_task_that_ends_within_the_call_keeps_it_inline(runner: InlineRunner) -> None:
    async def helper() -> int:
        return 7

    async def call() -> int:
        return await asyncio.get_running_loop().create_task(helper())

    assert runner.run(call()) == 7
    assert runner.inline


def test_a_second_thread_hands_the_loop_over(runner: InlineRunner) -> None:
    assert runner.run(_here()) == threading.get_ident()
    result: list[int] = []
    other = threading.Thread(target=lambda: result.append(runner.run(_here())))
    other.start()
    other.join(WAIT_S)
    assert result and not runner.inline
    assert result[0] not in (threading.get_ident(), other.ident)  # the loop thread's
    assert runner.run(_here()) == result[0]  # the first thread's calls follow


def test_a_second_thread_does_not_wait_for_a_call_in_progress(runner: InlineRunner) -> None:
    """A long call (a wait_idle, a monitor) on the owner's thread lets go of the loop when
    another thread calls (a stop!): the other call runs now, the long one finishes after."""
    waiting = threading.Event()
    box: list[asyncio.Event] = []

    async def long_call() -> str:
        box.append(asyncio.Event())
        waiting.set()
        await box[0].wait()
        return "released by the other thread's call"

    async def release() -> int:
        box[0].set()
        return threading.get_ident()

    result: list[int] = []

    def other() -> None:
        assert waiting.wait(WAIT_S)
        result.append(runner.run(release()))

    helper = threading.Thread(target=other)
    helper.start()
    try:
        assert runner.run(long_call()) == "released by the other thread's call"
    finally:
        helper.join(WAIT_S)
    assert result and not runner.inline
    assert runner.run(_here()) == result[0]  # both on the loop thread from now on


def test_a_timeout_holds_after_a_hand_over_in_mid_call(runner: InlineRunner) -> None:
    waiting = threading.Event()
    cancelled = threading.Event()

    async def hang() -> None:
        waiting.set()
        try:
            await asyncio.Event().wait()
        except asyncio.CancelledError:
            cancelled.set()
            raise

    def other() -> None:
        assert waiting.wait(WAIT_S)
        runner.run(_here())  # takes the loop to a loop thread while hang() waits

    helper = threading.Thread(target=other)
    helper.start()
    try:
        with pytest.raises(DriveTimeout):  # typed, as every servobus error
            runner.run(hang(), timeout=1.0)
    finally:
        helper.join(WAIT_S)
    assert not runner.inline and cancelled.wait(WAIT_S)


def test_a_stop_from_another_thread_ends_a_call_in_progress(runner: InlineRunner) -> None:
    """A call is not left waiting on a loop that another thread stopped under it."""
    waiting = threading.Event()

    async def forever() -> None:
        waiting.set()
        await asyncio.Event().wait()

    def other() -> None:
        assert waiting.wait(WAIT_S)
        runner.stop()

    helper = threading.Thread(target=other)
    helper.start()
    try:
        with pytest.raises(RuntimeError, match="closed"):
            runner.run(forever())
    finally:
        helper.join(WAIT_S)
    assert runner.stopped


def test_a_caller_with_a_loop_of_its_own_hands_the_loop_over(runner: InlineRunner) -> None:
    async def notebook_cell() -> int:  # Jupyter runs cells on a running loop
        return runner.run(_here())

    assert asyncio.run(notebook_cell()) != threading.get_ident()
    assert not runner.inline


def test_ctrl_c_in_a_wait_cancels_the_call_and_unwinds_it(runner: InlineRunner) -> None:
    unwound = threading.Event()

    def interrupt() -> None:
        raise KeyboardInterrupt  # what the signal handler raises while the selector waits

    async def wait_for_reply() -> None:
        asyncio.get_running_loop().call_later(0.01, interrupt)
        try:
            await asyncio.Event().wait()
        except asyncio.CancelledError:
            unwound.set()  # the transaction's own cleanup (the reply is owed) runs here
            raise

    with pytest.raises(KeyboardInterrupt):
        runner.run(wait_for_reply())
    assert unwound.is_set()
    assert runner.run(_here()) == threading.get_ident()  # the next call runs as before


def test_stop_closes_the_loop_and_refuses_calls(runner: InlineRunner) -> None:
    runner.run(_here())
    runner.stop()
    assert runner.loop.is_closed() and runner.stopped
    coro = _here()
    with pytest.raises(RuntimeError, match="closed"):
        runner.run(coro)


def test_servobus_sync_thread_turns_it_off(monkeypatch: pytest.MonkeyPatch) -> None:
    assert inline.available()  # Linux, CPython: asyncio's loop has _run_once
    monkeypatch.setenv(inline.ENV, "thread")
    assert not inline.available()
