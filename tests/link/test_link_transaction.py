"""The shared TransactionManager on a scripted medium, without any protocol.

The medium's requests are keys (str) and its replies ints; a script says per request how the
"drive" answers (at once, after a delay, never, corrupt). Each rule of the manager's module
docstring is checked here once; the DYN232M and DYN CAN client tests check that both clients
keep them on their real media.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import time
from collections import deque
from dataclasses import dataclass

import pytest
from rig import wait_until_async

from servobus.errors import (
    ArgumentRangeError,
    ChecksumError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
    EepromGuardError,
    FramingError,
)
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.transaction import TransactionManager, TransactionStats, check_call
from servobus.transport.base import Direction

pytestmark = pytest.mark.timeout(20)
DEADLINE_S = 0.05
EARLY_S = 0.001  # timer granularity: a deadline never fires earlier than this
MARGIN_S = 0.15  # loaded machine: only upper bounds use it
NOW, NEVER, CORRUPT = 0.0, None, "corrupt"


@dataclass
class Answer:
    value: int
    delay: float | str | None = NOW  # seconds, NEVER, or CORRUPT


class ScriptedMedium:
    """Answers each request as scripted (default: at once with ``value``); records when each
    write's bytes left. ``write_s`` makes writes take that long before they leave."""

    def __init__(self) -> None:
        self.tm: TransactionManager[str, str, int] | None = None
        self.script: deque[Answer] = deque()
        self.value = 7
        self.left: list[tuple[float, str]] = []
        self.write_s: deque[float] = deque()
        self.fail_write: BaseException | None = None

    async def write(self, key: str) -> None:
        if self.fail_write is not None:
            raise self.fail_write
        if self.write_s:
            await asyncio.sleep(self.write_s.popleft())  # scripted: a write draining at wire speed
        self.left.append((time.monotonic(), key))
        answer = self.script.popleft() if self.script else Answer(self.value)
        if answer.delay is NEVER:
            return
        assert self.tm is not None
        tm = self.tm
        if answer.delay == CORRUPT:
            asyncio.get_running_loop().call_soon(tm.reject, ChecksumError("bad checksum"))
            return
        assert isinstance(answer.delay, float)
        asyncio.get_running_loop().call_later(answer.delay, self.arrive, key, answer.value)

    def arrive(self, key: str, value: int) -> None:
        assert self.tm is not None
        if not (self.tm.answer(key, value) or self.tm.late(key)):
            self.tm.stray((key, value))


def manager(medium: ScriptedMedium, **options: object) -> TransactionManager[str, str, int]:
    tm: TransactionManager[str, str, int] = TransactionManager(
        medium.write, link="test link", describe_key=lambda k: f"reply {k}",
        describe_request=lambda k: f"drive 1 to {k}", **options)  # type: ignore[arg-type]
    medium.tm = tm
    return tm


async def read(tm: TransactionManager[str, str, int], key: str = "status", **kw: object) -> int:
    kw.setdefault("deadline_s", DEADLINE_S)
    return await tm.request(key, key, retry_safe=True, **kw)  # type: ignore[arg-type]


# ---------------------------------------------------------------------- attempts
async def test_a_reply_is_returned_and_counted() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    assert await read(tm) == 7
    assert tm.stats == TransactionStats(sent=1, replies=1)


async def test_reads_are_retried_and_give_up_with_drive_timeout() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=2, late_reply_s=0.0)
    m.script.extend([Answer(1, NEVER)] * 3)
    t0 = time.monotonic()
    with pytest.raises(DriveTimeout, match="no reply from drive 1 to status after 3 attempt"):
        await read(tm)
    assert time.monotonic() - t0 >= 3 * DEADLINE_S - EARLY_S
    assert tm.stats == TransactionStats(sent=3, retries=2, timeouts=3)


async def test_a_write_with_a_reply_is_sent_exactly_once() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=5)
    m.script.append(Answer(1, NEVER))
    with pytest.raises(DriveTimeout, match="after 1 attempt"):
        await tm.request("set", "set", deadline_s=DEADLINE_S, retry_safe=False)
    assert [k for _, k in m.left] == ["set"] and tm.stats.retries == 0


async def test_per_call_retries_override_the_default() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=5, late_reply_s=0.0)
    m.script.extend([Answer(1, NEVER)] * 6)
    with pytest.raises(DriveTimeout):
        await read(tm, retries=0)
    assert tm.stats.sent == 1


async def test_deadline_runs_from_when_the_bytes_left() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=0)
    m.write_s.append(0.1)  # the write itself takes 100 ms (a draining serial port)
    m.script.append(Answer(5, 0.03))  # 130 ms after the send was decided, 30 ms after it left
    assert await read(tm) == 5


async def test_a_corrupt_reply_fails_its_attempt_and_the_read_is_retried() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    m.script.append(Answer(0, CORRUPT))
    assert await read(tm) == 7
    assert tm.stats.retries == 1 and tm.stats.timeouts == 0
    m.script.extend([Answer(0, CORRUPT)] * 3)
    with pytest.raises(ChecksumError):
        await read(tm)


async def test_another_rejection_ends_the_call_without_a_retry() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    m.script.append(Answer(0, NEVER))
    loop = asyncio.get_running_loop()
    loop.call_later(0.01, tm.reject, DriveError("drive error 0xff", code=0xFF), "status")
    with pytest.raises(DriveError):
        await read(tm)
    assert tm.stats.sent == 1 and tm.stats.retries == 0


# ---------------------------------------------------------------------- late replies
async def test_a_late_reply_never_answers_the_next_request() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=0, late_reply_s=60.0)
    m.script.append(Answer(111, 2 * DEADLINE_S))  # arrives after its deadline
    with pytest.raises(DriveTimeout):
        await read(tm)
    m.script.append(Answer(222))
    t0 = time.monotonic()
    assert await read(tm) == 222  # waited for the owed reply, then asked
    # Ended by the late reply, not the 60 s bound (far from anything a loaded machine takes).
    assert time.monotonic() - t0 < 15.0
    assert tm.stats.late_replies == 1 == tm.late_replies.late


async def test_other_keys_never_wait_for_an_owed_reply() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=0, late_reply_s=60.0)
    m.script.append(Answer(111, NEVER))
    with pytest.raises(DriveTimeout):
        await read(tm, "status")
    t0 = time.monotonic()
    assert await read(tm, "position") == 7
    assert time.monotonic() - t0 < 15.0  # no wait for the owed reply (that would be 60 s)
    assert tm.late_replies.drains == 0


async def test_strays_are_counted_by_kind() -> None:
    tm = manager(ScriptedMedium())
    for item in (ChecksumError("x"), FramingError("y"), ("status", 3)):
        tm.stray(item)
    assert (tm.stats.checksum_errors, tm.stats.framing_errors, tm.stats.unmatched) == (1, 1, 1)
    assert not tm.answer("status", 3)  # nothing waits


# ---------------------------------------------------------------------- pacing
async def test_pacing_is_measured_at_the_bytes_on_the_wire() -> None:
    """Regression (issue #9): the pacing clock was stamped when a send was decided, so a
    write that took long (a loaded host, a draining port) let the next request leave
    early. Here the first write takes 15 ms before its bytes leave: stamped at the
    decision, the next request would leave 5 ms after it."""
    m = ScriptedMedium()
    interval = 0.02
    tm = manager(m, query_interval_s=interval)
    m.write_s.extend([0.015, 0.0, 0.012, 0.0])
    for _ in range(4):
        await read(tm)
    times = [t for t, _ in m.left]
    gaps = [later - earlier for earlier, later in itertools.pairwise(times)]
    assert min(gaps) >= interval, gaps


async def test_commands_without_a_reply_are_not_paced() -> None:
    m = ScriptedMedium()
    tm = manager(m, query_interval_s=60.0)
    await read(tm)
    t0 = time.monotonic()
    await tm.send("move")
    await tm.send("move")
    # Not paced: far from the 60 s interval a paced send would wait.
    assert time.monotonic() - t0 < 15.0 and tm.stats.sent == 3


# ---------------------------------------------------------------------- lanes
async def test_lanes_run_concurrently_and_one_lane_serially() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    m.script.extend([Answer(1, 0.03), Answer(2, 0.03)])
    t0 = time.monotonic()
    got = await asyncio.gather(
        tm.request("a", "a", deadline_s=1.0, retry_safe=True, lane=1),
        tm.request("b", "b", deadline_s=1.0, retry_safe=True, lane=2))
    assert list(got) == [1, 2] and time.monotonic() - t0 < 0.06 + MARGIN_S
    m.script.extend([Answer(3, 0.03), Answer(4, 0.03)])
    order: list[str] = []

    async def one(key: str) -> None:
        await tm.request(key, key, deadline_s=1.0, retry_safe=True, lane=1)
        order.append(key)

    await asyncio.gather(one("c"), one("d"))
    assert order == ["c", "d"] and [k for _, k in m.left][-2:] == ["c", "d"]


async def test_one_timer_expires_waiters_of_different_deadlines_on_time() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=0, late_reply_s=0.0)
    m.script.extend([Answer(0, NEVER)] * 3)
    loop = asyncio.get_running_loop()

    async def timed(key: str, deadline: float) -> float:
        t0 = loop.time()
        with pytest.raises(DriveTimeout):
            await tm.request(key, key, deadline_s=deadline, retry_safe=True, lane=key)
        return loop.time() - t0

    deadlines = (0.15, 0.05, 0.1)
    took = await asyncio.gather(*(timed(k, d) for k, d in zip("abc", deadlines, strict=True)))
    for t, d in zip(took, deadlines, strict=True):
        assert d - EARLY_S <= t <= d + MARGIN_S


# ---------------------------------------------------------------------- the end of the link
async def test_a_lost_link_fails_the_waiting_request_at_once_and_every_later_call() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    m.script.append(Answer(0, NEVER))
    asyncio.get_running_loop().call_later(0.01, tm.lost, BrokenPipeError("gone"))
    t0 = time.monotonic()
    with pytest.raises(ConnectionLost, match="test link lost: gone while waiting for reply"):
        await tm.request("status", "status", deadline_s=60.0, retry_safe=True)
    assert time.monotonic() - t0 < 15.0  # the loss failed it, not the 60 s deadline
    for call in (read(tm), tm.send("move")):
        with pytest.raises(ConnectionLost):
            await call


async def test_a_failing_write_is_connection_lost() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    m.fail_write = ConnectionResetError("reset by peer")
    with pytest.raises(ConnectionLost):
        await read(tm)
    assert tm.dead is not None
    with pytest.raises(ConnectionLost):
        tm.check_alive()


async def test_close_ends_waiting_and_later_calls() -> None:
    m = ScriptedMedium()
    tm = manager(m)
    m.script.append(Answer(0, NEVER))
    task = asyncio.ensure_future(read(tm, deadline_s=60.0))  # waiting until the close
    await wait_until_async(lambda: m.left, what="the request sent")  # now waiting
    assert tm.close() is True and tm.close() is False and tm.closed
    with pytest.raises(ConnectionLost, match="client is closed"):
        await task
    with pytest.raises(ConnectionLost):
        await read(tm)


# ---------------------------------------------------------------------- pull media
class PullMedium(ScriptedMedium):
    """A medium that can only be read: replies wait in a queue until pulled."""

    def __init__(self) -> None:
        super().__init__()
        self.queue: asyncio.Queue[tuple[str, int]] = asyncio.Queue()
        self.flushes = 0

    def arrive(self, key: str, value: int) -> None:
        self.queue.put_nowait((key, value))

    async def pull(self) -> None:
        key, value = await self.queue.get()
        super().arrive(key, value)

    def flush(self) -> None:
        self.flushes += 1
        while not self.queue.empty():
            self.queue.get_nowait()


async def test_pull_media_take_the_same_rules() -> None:
    m = PullMedium()
    tm = manager(m, retries=1, late_reply_s=1.0, pull=m.pull, flush=m.flush)
    assert await read(tm) == 7
    m.script.extend([Answer(1, NEVER), Answer(9)])
    assert await read(tm) == 9  # retried after a timeout
    assert m.flushes == 3  # before every attempt
    m.script.extend([Answer(0, NEVER)] * 2)
    with pytest.raises(DriveTimeout):
        await read(tm)
    m.script.append(Answer(111, 0.0))  # ...now both late ones come, then ours
    m.arrive("status", 1)
    m.arrive("status", 2)
    assert await read(tm) == 111  # buffered late replies paid their debts, not dropped
    assert tm.stats.late_replies >= 2


async def test_a_pull_read_error_is_connection_lost() -> None:
    m = PullMedium()

    async def broken() -> None:
        raise ConnectionResetError("unplugged")

    tm = manager(m, pull=broken)
    with pytest.raises(ConnectionLost):
        await read(tm)


# ---------------------------------------------------------------------- checks
def test_per_call_knobs_are_checked() -> None:
    check_call(None, None)
    check_call(0, 0.5)
    for retries, timeout in ((-1, None), (1.5, None), (None, 0), (None, float("nan"))):
        with pytest.raises(ArgumentRangeError):
            check_call(retries, timeout)


def test_options_are_checked() -> None:
    for option, bad in (("retries", -1), ("query_interval_s", -0.1),
                        ("late_reply_s", float("inf"))):
        with pytest.raises(ArgumentRangeError, match=option):
            manager(ScriptedMedium(), **{option: bad})


def test_eeprom_refusal_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    tm = manager(ScriptedMedium(), eeprom_guard=EepromGuard(warn_per_window=100,
                                                           max_per_window=1))
    tm.check_eeprom(1, "main_gain")
    with caplog.at_level(logging.WARNING, logger="servobus"), \
            pytest.raises(EepromGuardError):
        tm.check_eeprom(1, "main_gain")
    assert any("main_gain" in r.getMessage() and r.levelno == logging.WARNING
               for r in caplog.records)


async def test_trace_sees_requests_and_timeouts() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=0, trace_request=lambda k: f"<{k}>")
    seen: list[tuple[Direction, object]] = []
    tm.add_trace(lambda d, item, t: seen.append((d, item)))
    assert tm.tracing
    m.script.append(Answer(0, NEVER))
    with pytest.raises(DriveTimeout):
        await read(tm)
    assert seen[0] == (Direction.TX, "<status>")
    assert seen[1][0] is Direction.RX and isinstance(seen[1][1], DriveTimeout)


# ---------------------------------------------------------------------- a stalled host
def turns_then(n: int, callback: object, *args: object) -> None:
    """``callback(*args)`` after ``n`` more loop turns (an in-process drive's reply path)."""
    loop = asyncio.get_running_loop()
    if n == 0:
        callback(*args)  # type: ignore[operator]
    else:
        loop.call_soon(turns_then, n - 1, callback, *args)


async def test_a_reply_on_its_way_through_a_stall_is_not_a_timeout() -> None:
    """The whole process stalls (here: the loop blocked) past the deadline while the reply
    is a few loop turns from delivery: the write-once request is answered, not timed out
    (module docstring: a stalled host is not a silent drive)."""
    m = ScriptedMedium()
    tm = manager(m, retries=0)
    m.script.append(Answer(1, NEVER))

    async def once() -> int:
        return await tm.request("move", "move", deadline_s=DEADLINE_S, retry_safe=False)

    call = asyncio.create_task(once())
    await wait_until_async(lambda: m.left, what="the request left")
    turns_then(3, m.arrive, "move", 5)
    time.sleep(3 * DEADLINE_S)  # the stall under test: the loop gets no turn
    assert await call == 5
    assert tm.stats.timeouts == 0


async def test_after_a_stall_a_silent_drive_still_times_out_once_graced() -> None:
    m = ScriptedMedium()
    tm = manager(m, retries=0, late_reply_s=0.0)
    m.script.append(Answer(1, NEVER))
    call = asyncio.create_task(tm.request("move", "move", deadline_s=DEADLINE_S,
                                          retry_safe=False))
    await wait_until_async(lambda: m.left, what="the request left")
    time.sleep(3 * DEADLINE_S)  # a stall, and no reply ever
    with pytest.raises(DriveTimeout, match="after 1 attempt"):
        await call
    assert tm.stats.timeouts == 1
