"""Sample every axis of a machine: position, speed, current and status, link by link.

How the rate is shared (decision, docs/gateway.md "Sampling"): axes are grouped by their
link (the axis URL: one serial line, bus or TCP connection). Each link has one sampling
loop; a round asks every axis of the link at once for its readings (position, speed and
status, then its current) and lets the link's transaction layer queue them (a serial line
carries them one after the other, a CAN bus overlaps the drives' answers); every axis gets
one sample per round, so each has the same share. Then the loop waits: a round is due
every ``1 / rate`` seconds (counted from when the previous one was due, not from its late
start: :func:`pause_after`), but never sooner than the last round's own duration (or the
running average of the last rounds' durations when smaller, :func:`typical_round`) times
``(1 - duty) / duty`` after it ended.
With the default duty of 0.5, sampling takes at most half of what a link can carry and
the other half stays free for commands. The per-axis rate is therefore
``min(rate, duty / time of one round)`` - measured, not configured, so a 38,400 baud line
with four drives settles at what it can carry while a fast link reaches the configured
rate. ``achieved_hz`` holds what each link reached; it is logged once per link after the
first seconds.

A read that fails (the link dropped, the drive did not answer, the axis is offline) gives
a Bad sample with the error's text once :data:`BAD_AFTER` rounds in a row have failed (an
offline axis at once): one lost answer on a busy link leaves the last good sample
standing rather than flapping every value to Bad and back. The sampling goes on and the
next good read makes the axis good again. A change between good and bad is logged in one
line, except where the axis went offline or came back online: the machine logs that, once
per link (decision: one line per event, not one per axis more).

Every sample also carries the axis's :class:`Health` (online, the time of its last good
call, a power loss or an interrupted motion waiting for an acknowledgement: docs/machine.md
"Recovery"), and after each round the link's :class:`~servobus.gateway.link_events.LinkWatch`
tells whether the link went down or came back (one event each, never one per retry).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from servobus.axis.types import AxisStatus
from servobus.errors import NotSupported
from servobus.gateway.commands import status_name
from servobus.gateway.link_events import LinkListener, LinkWatch
from servobus.gateway.source import Machine, MachineAxis

log = logging.getLogger(__name__)

DEFAULT_RATE_HZ = 20.0
DEFAULT_DUTY = 0.5
#: A whole axis read (four transactions) that takes longer than this is a failed read.
READ_DEADLINE_S = 2.0
#: Rounds in a row that must fail before an axis's values turn Bad.
BAD_AFTER = 3
OFFLINE = "axis offline"
#: Weight of the newest round in the running average of round durations (typical_round).
ROUND_WEIGHT = 0.2


@dataclass(frozen=True)
class Health:
    """What the machine knows of an axis beside its readings (issue 29): is its link up,
    when did a call on it last succeed (``time.time()``), and what waits for an
    acknowledgement (a possible power loss, an interrupted motion)."""

    online: bool = True
    last_good: float | None = None
    power_lost: bool = False
    power_lost_reason: str | None = None
    interrupted: str | None = None


def health_of(axis: MachineAxis) -> Health:
    return Health(axis.online, axis.last_good, axis.power_lost, axis.power_lost_reason,
                  axis.interrupted)


@dataclass(frozen=True)
class Sample:
    """One axis at one time (wall clock, seconds); ``ok`` False carries ``error`` and
    ``code``, the OPC UA status code name its values carry."""

    axis: str
    time: float
    ok: bool
    error: str = ""
    position: float = math.nan
    speed: float = math.nan
    current: float | None = None
    status: AxisStatus | None = None
    health: Health = Health()
    code: str = "Good"


def offline_code(last_good: float | None) -> str:
    """The status of an offline axis's values (decision, docs/gateway.md "Recovery"):
    BadCommunicationError once it has been read, BadNoCommunication ("defined, but not
    established, and there is no last known value") while it never was."""
    return "BadCommunicationError" if last_good is not None else "BadNoCommunication"


Listener = Callable[[Sample], None]


def pause_after(period: float, due: float, ended: float, duty: float,
                took: float | None = None) -> float:
    """Seconds to wait after a round that was due at ``due`` and ended at ``ended``: to
    one period after ``due``, and at least so long that the round took no more than
    ``duty`` of the time (the rest is left for commands). ``took`` is the round's duration
    to count (by default ``ended - due``).

    ``due`` is when the round was due, not when it started (decision): the loop wakes
    late (to the millisecond on epoll, later on a loaded machine), and counting the
    period from the late start lost that lateness at every round - 50 Hz of instant reads
    settled at 38 - 40 Hz at a load average of 10 on 2 cores. Counted from the due time
    the lateness is made up within the period, while a round later than a whole period
    moves the schedule on (no burst of rounds to catch up)."""
    if took is None:
        took = ended - due
    return max(due + period - ended, took * (1 - duty) / duty)


def typical_round(took: float, average: float | None) -> tuple[float, float]:
    """(duration the duty counts, new running average) for a round that took ``took``.

    The duty counts the smaller of this round and the running average (weight
    :data:`ROUND_WEIGHT` per round): a steadily slow link settles exactly as before, but
    one round stretched by a busy event loop or a command in between does not hold back
    the next round by its whole length (that stretched the delay of a change to 100-200 ms
    with 32 axes at 50 Hz)."""
    average = took if average is None else average + ROUND_WEIGHT * (took - average)
    return min(took, average), average


class RoundClock:
    """When a link's next round is due: :func:`typical_round` and :func:`pause_after`,
    with the due time kept from round to round."""

    def __init__(self, period: float, duty: float, now: float) -> None:
        self.period, self.duty = period, duty
        self.due = now
        self._average: float | None = None

    def rest(self, start: float, end: float) -> float:
        """Seconds to wait after a round that started at ``start`` and ended at ``end``."""
        took, self._average = typical_round(end - start, self._average)
        rest = pause_after(self.period, self.due, end, self.duty, took)
        self.due = end + rest
        return rest


def check_rate(rate_hz: float) -> float:
    if not (math.isfinite(rate_hz) and 0.1 <= rate_hz <= 1000):
        raise ValueError(f"sampling rate {rate_hz!r} Hz: give 0.1..1000")
    return rate_hz


class Sampler:
    """One loop per link; :attr:`latest` holds each axis's last sample."""

    def __init__(self, machine: Machine, rate_hz: float = DEFAULT_RATE_HZ,
                 duty: float = DEFAULT_DUTY) -> None:
        self.machine = machine
        self.rate_hz = check_rate(rate_hz)
        if not 0.05 <= duty <= 1.0:
            raise ValueError("duty must be 0.05..1")
        self.duty = duty
        self.links: dict[str, list[MachineAxis]] = {}
        for axis in machine.axes.values():
            self.links.setdefault(axis.url, []).append(axis)
        self.latest: dict[str, Sample] = {}
        self.listeners: list[Listener] = []
        self.achieved_hz: dict[str, float] = dict.fromkeys(self.links, 0.0)
        self._no_current: set[str] = set()
        self._failures: dict[str, int] = {}
        self._told_bad: set[str] = set()  # axes whose "no readings" line stands (_log_change)
        self.first_round = asyncio.Event()
        self._first_pending = set(self.links)
        self.watch = LinkWatch()
        self.link_listeners: list[LinkListener] = []

    async def run(self) -> None:
        """Sample until cancelled."""
        await asyncio.gather(*(self._link_loop(url, axes) for url, axes in self.links.items()))

    async def sample_once(self, axis: MachineAxis) -> Sample:
        try:
            # asyncio.timeout, not wait_for: 3.11's wait_for can swallow a cancellation that
            # meets a read just finishing, and the loop would never end
            async with asyncio.timeout(READ_DEADLINE_S):
                return await self._read(axis)
        except asyncio.CancelledError:
            raise
        except TimeoutError as exc:
            return _failed(axis, str(exc) or "no answer in time", "BadTimeout")
        except Exception as exc:  # any failure of the link or drive is a Bad sample
            return _failed(axis, f"{type(exc).__name__}: {exc}", status_name(exc))

    async def _read(self, axis: MachineAxis) -> Sample:
        if not axis.online:
            why = axis.last_error
            return _failed(axis, OFFLINE if why is None else f"{OFFLINE}: {why}",
                           offline_code(axis.last_good))
        # one after the other, not gathered (decision): a drive's requests queue on its
        # lane anyway (the whole line on serial links, the drive on CAN), so the two tasks
        # and the lane's waiters of a gather bought nothing but about 35 us of CPU per
        # sample; only an EtherNet/IP session with max_in_flight > 1 overlapped them (one
        # round trip more per round, well within a period)
        position, speed, status = await axis.readings()
        current = await self._current(axis)
        return Sample(axis.name, time.time(), True, "", position, speed, current, status,
                      health_of(axis))

    async def _current(self, axis: MachineAxis) -> float | None:
        raw = axis.axis
        if raw is None or axis.name in self._no_current:
            return None
        try:
            return await raw.current()
        except NotSupported:
            self._no_current.add(axis.name)
            return None

    def _publish(self, sample: Sample) -> None:
        before = self.latest.get(sample.axis)
        offline = not sample.health.online
        if sample.ok:
            self._failures[sample.axis] = 0
        else:
            failures = self._failures[sample.axis] = self._failures.get(sample.axis, 0) + 1
            if before is not None and before.ok and failures < BAD_AFTER and not offline:
                return  # a lost answer: the last good sample stands
        self._log_change(before, sample)
        self.latest[sample.axis] = sample
        for listener in self.listeners:
            try:
                listener(sample)
            except Exception:
                log.exception("sample listener failed")

    def _log_change(self, before: Sample | None, sample: Sample) -> None:
        """One line when an axis's readings turn Bad while its link is online, and one
        when they are back after that line; a spell that goes offline is the machine's to
        tell (its own lines about the link), and no line of ours ends it.

        Decision: "readings are back" answers a "no readings" line, never stands alone. It
        was keyed on the last Bad sample being online: a read that timed out just after the
        link came back (a spell that began offline) added an unpaired "back" line
        (test_gateway_restart[dyncan], one run in six beside two CPU hogs)."""
        name = sample.axis
        if sample.ok:
            if name in self._told_bad:
                log.info("axis %s: readings are back", name)
            self._told_bad.discard(name)
        elif not sample.health.online:
            self._told_bad.discard(name)  # from here the machine's link lines say it
        elif before is None or before.ok:
            log.warning("axis %s: no readings: %s", name, sample.error)
            self._told_bad.add(name)

    def _watch_link(self, url: str, axes: list[MachineAxis]) -> None:
        for event in self.watch.observe(url, axes):
            for listener in self.link_listeners:
                try:
                    listener(event)
                except Exception:
                    log.exception("link listener failed")

    async def _link_loop(self, url: str, axes: list[MachineAxis]) -> None:
        loop = asyncio.get_running_loop()
        rounds, since = 0, loop.time()
        clock = RoundClock(1.0 / self.rate_hz, self.duty, loop.time())
        while True:
            start = loop.time()
            for sample in await asyncio.gather(*(self.sample_once(a) for a in axes)):
                self._publish(sample)
            self._watch_link(url, axes)
            end = loop.time()
            if url in self._first_pending:
                self._first_pending.discard(url)
                if not self._first_pending:
                    self.first_round.set()
            rest = clock.rest(start, end)
            rounds += 1
            if end - since >= 2.0:
                if not self.achieved_hz[url]:
                    log.info("link %s: %d axes sampled at %.1f Hz each", url, len(axes),
                             rounds / (end - since))
                self.achieved_hz[url] = rounds / (end - since)
                rounds, since = 0, end
            await asyncio.sleep(rest)


def _failed(axis: MachineAxis, error: str, code: str) -> Sample:
    return Sample(axis.name, time.time(), False, error, health=health_of(axis), code=code)


