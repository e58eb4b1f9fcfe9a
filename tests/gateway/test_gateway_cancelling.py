"""An MQTT session ends on a stop even when a cancellation was swallowed below it
(servobus.gateway.cancelling): Python 3.11's ``asyncio.wait_for``, which aiomqtt's
publish, connect and subscribe use, returns the result instead of raising CancelledError
when both arrive in one loop iteration. Stand-in tasks swallow the first cancellation as it
does; before the fix ``Gateway.close`` waited for such a session for ever."""

from __future__ import annotations

import asyncio
import contextlib
import logging

import pytest

from servobus.gateway.cancelling import cancel_until_ended
from servobus.gateway.mqtt import Broker, keep_connected, run_session

DEADLINE_S = 30.0  # a hang fails here instead of at the suite's timeout


async def swallow_first_cancel(started: asyncio.Event) -> None:
    """Runs on after its first cancellation, as a loop whose wait_for swallowed it."""
    started.set()
    # what 3.11's wait_for does when the publish's acknowledgement came with the cancel
    with contextlib.suppress(asyncio.CancelledError):
        await asyncio.sleep(3600)
    await asyncio.sleep(3600)


async def test_cancel_until_ended_ends_a_task_that_swallowed_its_cancellation() -> None:
    started = asyncio.Event()
    task = asyncio.create_task(swallow_first_cancel(started))
    await started.wait()
    async with asyncio.timeout(DEADLINE_S):
        await cancel_until_ended([task])
    assert task.cancelled()


async def test_a_stopped_session_ends_and_says_farewell_though_a_task_swallowed_the_stop(
) -> None:
    started = asyncio.Event()
    farewells: list[str] = []

    async def farewell() -> None:
        farewells.append("offline")

    session = asyncio.create_task(run_session(
        [asyncio.create_task(swallow_first_cancel(started))], farewell))
    await started.wait()
    session.cancel()  # the gateway's close
    async with asyncio.timeout(DEADLINE_S):
        with pytest.raises(asyncio.CancelledError):
            await session
    assert farewells == ["offline"]  # the clean stop's offline message / NDEATH


async def test_a_stop_swallowed_while_connecting_starts_no_new_session() -> None:
    connects: list[int] = []
    started = asyncio.Event()

    async def connect() -> None:  # the stop arrives while aiomqtt connects, and is lost
        connects.append(1)
        started.set()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.sleep(3600)

    task = asyncio.create_task(keep_connected(
        connect, asyncio.Event(), "MQTT broker", Broker("127.0.0.1", 1, False, None, None),
        logging.getLogger(__name__)))
    await started.wait()
    task.cancel()
    async with asyncio.timeout(DEADLINE_S):
        with pytest.raises(asyncio.CancelledError):
            await task
    assert connects == [1]
