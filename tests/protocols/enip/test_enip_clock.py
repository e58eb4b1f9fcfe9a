"""The Class 1 clock thread (issue 22): absolute deadlines on a fake clock, no drift."""

from __future__ import annotations

import pytest

from servobus.protocols.enip.clock import ClockThread, next_due
from servobus.protocols.enip.scanner import CyclicIo

MS = 1_000_000


def test_next_due_stays_on_the_grid_whatever_the_lateness() -> None:
    assert next_due(10 * MS, 5 * MS, now_ns=10 * MS) == 15 * MS
    assert next_due(10 * MS, 5 * MS, now_ns=14 * MS) == 15 * MS  # 4 ms late: same grid
    assert next_due(10 * MS, 5 * MS, now_ns=19 * MS) == 15 * MS  # behind less than a period


def test_next_due_restarts_a_producer_more_than_a_period_behind() -> None:
    assert next_due(10 * MS, 5 * MS, now_ns=21 * MS) == 26 * MS  # no burst of catch-ups


class FakeClock:
    def __init__(self) -> None:
        self.t = 1_000 * MS

    def __call__(self) -> int:
        return self.t


def test_frames_leave_on_absolute_deadlines_without_drift() -> None:
    """Each wake-up 0.3 ms late: every frame is still due first + k * period (a relative
    "now + period" schedule would have drifted by 0.3 ms per frame)."""
    clock = FakeClock()
    sent: list[int] = []
    thread = ClockThread(realtime=False, now_ns=clock)
    thread._started = True  # driven by step() on this thread, not started
    first = clock.t
    thread.add(0.005, lambda: sent.append(clock.t))
    for k in range(200):
        clock.t = first + k * 5 * MS + 300_000  # the wake-up is late
        assert thread.step()
    assert len(sent) == 200
    assert [t - first - 300_000 for t in sent] == [k * 5 * MS for k in range(200)]
    assert thread.late_restarts == 0


def test_step_before_the_deadline_sends_nothing() -> None:
    clock = FakeClock()
    sent: list[int] = []
    thread = ClockThread(realtime=False, now_ns=clock)
    thread._started = True
    tick = thread.add(0.005, lambda: sent.append(clock.t))
    clock.t += 5 * MS  # the first frame (due at add) and now the second
    thread.step()
    assert len(sent) == 1 and tick.due_ns == clock.t
    thread.remove(tick)
    assert len(thread) == 0


def test_a_failing_producer_is_stopped_and_the_others_go_on() -> None:
    clock = FakeClock()
    sent: list[int] = []
    thread = ClockThread(realtime=False, now_ns=clock)
    thread._started = True

    def broken() -> None:
        raise ValueError("boom")

    thread.add(0.005, broken)
    thread.add(0.005, lambda: sent.append(clock.t))
    thread.step()
    clock.t += 5 * MS
    thread.step()
    assert len(sent) == 2 and len(thread) == 1


def test_clock_option_is_checked() -> None:
    with pytest.raises(Exception, match="clock must be"):
        CyclicIo(object(), clock="timerfd")  # type: ignore[arg-type]


def test_realtime_falls_back_with_one_log_line(monkeypatch: pytest.MonkeyPatch,
                                               caplog: pytest.LogCaptureFixture) -> None:
    import logging
    import os

    from servobus import thread_priority

    def refuse(*_: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.delenv(thread_priority.ENV, raising=False)
    monkeypatch.setattr(os, "sched_setscheduler", refuse, raising=False)
    monkeypatch.setattr(os, "SCHED_FIFO", 1, raising=False)
    with caplog.at_level(logging.INFO, logger="servobus.thread_priority"):
        assert thread_priority.request_realtime("test clock") is False
    assert len(caplog.records) == 1 and "CAP_SYS_NICE" in caplog.records[0].getMessage()


def test_realtime_off_by_env_asks_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    from servobus import thread_priority

    def must_not_run(*_: object) -> None:
        raise AssertionError("asked for SCHED_FIFO")

    monkeypatch.setenv(thread_priority.ENV, "0")
    monkeypatch.setattr(os, "sched_setscheduler", must_not_run, raising=False)
    assert thread_priority.request_realtime("test clock") is False


def test_producers_of_one_period_share_their_wake_ups() -> None:
    clock = FakeClock()
    sent: list[tuple[str, int]] = []
    thread = ClockThread(realtime=False, now_ns=clock)
    thread._started = True
    a = thread.add(0.005, lambda: sent.append(("a", clock.t)))
    clock.t += 2 * MS  # opened 2 ms later: joins a's grid instead of its own
    b = thread.add(0.005, lambda: sent.append(("b", clock.t)))
    assert b.due_ns == a.due_ns
    thread.step()
    assert [name for name, _ in sent] == ["a", "b"]
    assert a.due_ns == b.due_ns


def test_shared_clock_is_realtime_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from servobus.protocols.enip import clock

    monkeypatch.setattr(ClockThread, "_shared", None)
    monkeypatch.delenv(clock.CLOCK_REALTIME_ENV, raising=False)
    assert ClockThread.shared().realtime is False  # not started: no thread yet
    ClockThread.shared().stop()
    monkeypatch.setenv(clock.CLOCK_REALTIME_ENV, "1")
    assert ClockThread.shared().realtime is True
    ClockThread.shared().stop()
