"""AsyncMachine: every axis of a machine file, by name, in user units (docs/machine.md).

``open_machine_async(path)`` reads the file, opens each link once and applies the origin
rules. ``retry=False`` (scripts, the CLI): a link that cannot be opened is one
MachineLinkError naming the axis and its URL, and whatever was opened is closed again.
``retry=True`` (GUI, gateway): such an axis starts offline (``online`` False,
``last_error`` set) and a background task retries its link until it opens or the machine
closes.

Origin rules (``origin = "set"`` / ``"home"``; decision, issue 28): a rule is applied once per
machine, when its axis's link first opens; reopening a link never applies it again.
``origins=False`` applies none: the one-shot CLI commands open the machine that way, since a
command cannot know whether the drive was power-cycled since the last one. Applying the rule
at every command re-zeroed the axis where it stood each time (two ``move 90deg`` turned 180
deg and ``position`` read 0 after each), and on a DYN5 setting the origin resets the drive's
servo control. Long-running owners (GUI, gateway, a script) open with origins applied.

Recovery (issue 29, docs/machine.md "Recovery"), whatever ``retry`` says: a link that drops
(its transport says so, ``AsyncAxis.on_link_lost``, or a call on it fails with
ConnectionLost) takes its axes offline and is reopened with :func:`backoff` - the first try
at once, then after :data:`RETRY_S`, doubling to at most :data:`RETRY_MAX_S` between tries,
slept on the injected ``sleep`` (a test runs simulated minutes). One log line when a link
goes down, one when it is back; tries in between log at debug level only. A try counts
only when the link also answers its first reads (the power check, or a status read on a
link that never opened): a peer that accepts a connection and hangs up at once fails the
try quietly, and a link that drops again within :data:`STABLE_S` is not retried at once.
Nothing is resumed: no motion is re-sent, leases end, ``origin`` is never applied again;
after the link is back each axis is checked for a power loss
(AsyncMachineAxis.check_power).

``close()`` stops every axis first (servobus.axis.halt.halt), then closes the links. Any
call after it raises ClosedError.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from collections.abc import Awaitable, Callable, Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, TracebackType

from servobus.axis.base import AsyncAxis
from servobus.axis.halt import DEFAULT_HALT_TIMEOUT_S, halt
from servobus.errors import (
    ArgumentRangeError,
    ClosedError,
    LimitError,
    MachineLinkError,
    NotSupported,
    ServobusError,
)
from servobus.machine.axis import AsyncMachineAxis
from servobus.machine.builtin import BUILTIN_SOURCE, builtin_spec
from servobus.machine.config import MachineSpec, load_machine_file, url_spec
from servobus.machine.links import Link, group_links

log = logging.getLogger(__name__)

#: Reconnect backoff: the first try at once, then after RETRY_S, doubling to RETRY_MAX_S.
RETRY_S = 0.1
RETRY_MAX_S = 2.0
#: A link that drops again within STABLE_S of coming back is not retried at once: its first
#: try waits RETRY_S, doubled for each such drop in a row (at most RETRY_MAX_S), so whatever
#: a peer does, a link is not reopened in a tight loop. (Decision, the fault run of issue
#: 29: a peer that accepted a connection and hung up - a port forward whose drive is off -
#: was reopened in a tight loop, two log lines per turn; a try now also has to pass its
#: first reads, _verify.)
STABLE_S = 1.0

Sleep = Callable[[float], Awaitable[None]]


def backoff(*, at_once: bool = True, first: float = RETRY_S) -> Iterator[float]:
    """Seconds to wait before each reconnect try: 0 (``at_once``), 0.1 (``first``), 0.2 ...
    2, 2 ..."""
    if at_once:
        yield 0.0
    delay = first
    while True:
        yield delay
        delay = min(delay * 2, RETRY_MAX_S)


@dataclass(frozen=True)
class TogetherReport:
    """What :meth:`AsyncMachine.move_together` did.

    ``starts``: per axis, the ``time.perf_counter()`` at which its start was handed to the
    link (for axes started by one trigger: the trigger's). ``skew_s``: the latest minus the
    earliest start. ``groups``: the axes started together by one synchronised trigger.
    ``synchronised``: every axis started by one trigger.
    """

    starts: Mapping[str, float]
    groups: tuple[tuple[str, ...], ...] = field(default=())

    @property
    def skew_s(self) -> float:
        times = list(self.starts.values())
        return max(times) - min(times) if times else 0.0

    @property
    def synchronised(self) -> bool:
        return len(self.groups) == 1 and len(self.groups[0]) == len(self.starts)

    def as_dict(self) -> dict[str, object]:
        return {"skew_s": self.skew_s, "synchronised": self.synchronised,
                "groups": [list(g) for g in self.groups]}


class AsyncMachine:
    """Axes by name (ordered as in the file); see the module docstring."""

    def __init__(self, spec: MachineSpec, *, source: str, sleep: Sleep = asyncio.sleep) -> None:
        self.spec = spec
        self.source = source
        self._axes = {s.name: AsyncMachineAxis(s, source) for s in spec.axes}
        self.links = group_links(list(self._axes.values()), source)
        self._link_of = {a.name: link for link in self.links for a in link.axes}
        for axis in self._axes.values():
            axis.on_drop = self._axis_dropped
        self._sleep = sleep  # the reconnect clock (a test injects a simulated one)
        self._retries: set[asyncio.Task[None]] = set()
        self._guards: list[asyncio.Task[None]] = []
        self._closed = False
        self._origins = True
        self._origin_done: set[str] = set()  # axes whose origin rule ran (never again)
        #: Reconnect tries made (every link), for tests and the fault run.
        self.reconnect_tries = 0

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def path(self) -> Path | None:
        return self.spec.path

    @property
    def axes(self) -> Mapping[str, AsyncMachineAxis]:
        return MappingProxyType(self._axes)

    def __getitem__(self, name: str) -> AsyncMachineAxis:
        try:
            return self._axes[name]
        except KeyError:
            raise ArgumentRangeError(f"no axis {name!r} in {self.source}; axes: "
                                     f"{', '.join(self._axes)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._axes)

    def __len__(self) -> int:
        return len(self._axes)

    # ------------------------------------------------------------- opening
    @property
    def origins_skipped(self) -> tuple[str, ...]:
        """The online axes whose origin rule was not applied (opened with ``origins=False``)."""
        return tuple(name for name, a in self._axes.items()
                     if a.online and a.spec.origin != "none" and name not in self._origin_done)

    async def _open(self, retry: bool, only: Collection[str] | None = None,
                    origins: bool = True) -> None:
        self._origins = origins
        if only is not None:
            for name in only:
                self[name]  # the one line naming the axes
        for link in self.links:
            if only is not None and not any(a.name in only for a in link.axes):
                continue  # not asked for: stays offline, never opened
            try:
                await link.open()
                await self._apply_origins(link)
                await self._opened(link)
            except Exception as exc:
                if not retry or not _retryable(exc):
                    await self.close()
                    raise
                link.mark_offline(exc)
                log.warning("%s", exc)
                self._spawn(self._reconnect(link, backoff(at_once=False), first=True),
                            f"machine-retry {link.url}")

    async def _apply_origins(self, link: Link) -> None:
        """Each axis's origin rule, once per machine (module docstring)."""
        if not self._origins:
            return
        for axis in link.axes:
            if axis.name in self._origin_done:
                continue
            await axis.apply_origin()
            self._origin_done.add(axis.name)

    async def _opened(self, link: Link) -> None:
        """A link is open: watch its transport, leave the power token (where the family
        keeps one). A link that dropped again meanwhile is left to its own reopen."""
        for axis in link.axes:
            core = axis.axis
            if core is None:
                return
            core.on_link_lost(functools.partial(self._link_signal, asyncio.get_running_loop(),
                                                link, core))
            with contextlib.suppress(ServobusError):  # MachineLinkError: dropped again
                await axis.mark_power()

    def _spawn(self, coro: Awaitable[None], name: str) -> None:
        task = asyncio.ensure_future(coro)
        task.set_name(name)
        self._retries.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[None]) -> None:
        """A reopen task ended: one line if it failed (never asyncio's 'never retrieved')."""
        self._retries.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.warning("%s: %s failed: %s", self.source, task.get_name(), task.exception())

    # ------------------------------------------------------------- recovery
    def _axis_dropped(self, axis: AsyncMachineAxis, err: BaseException) -> None:
        link = self._link_of[axis.name]
        self._link_lost(link, axis.axis, err)

    def _link_signal(self, loop: asyncio.AbstractEventLoop, link: Link, core: AsyncAxis,
                     err: BaseException) -> None:
        """The transport's own signal (AsyncAxis.on_link_lost): handled on the loop, after
        the receive path that raised it has returned."""
        with contextlib.suppress(RuntimeError):  # the loop is closed: nothing to reopen
            loop.call_soon_threadsafe(self._link_lost, link, core, err)

    def _link_lost(self, link: Link, core: AsyncAxis | None, err: BaseException) -> None:
        """A link dropped (a failed call or its transport's signal; called once or many
        times, from any of its axes): offline now, reopened by a task."""
        if self._closed or core is None or core not in link.cores():
            return  # closed, already offline, or a signal of a link reopened since
        cause = err.__cause__ if isinstance(err, MachineLinkError) and err.__cause__ else err
        cores = link.take_offline(err if isinstance(err, MachineLinkError) else
                                  MachineLinkError(f"the link {link.url} is down: {err}"))
        if link.verifying:  # a reopen try whose first reads failed: _reconnect goes on
            log.debug("%s: link %s dropped again at once (%s)", self.source, link.url, cause)
            self._spawn(_close(cores), f"machine-close {link.url}")
            return
        log.warning("%s: link %s is down (%s); reopening it", self.source, link.url, cause)
        self._spawn(self._recover(link, cores), f"machine-reopen {link.url}")

    async def _recover(self, link: Link, cores: Sequence[AsyncAxis]) -> None:
        await _close(cores)
        if time.monotonic() - link.up_since < STABLE_S:  # it came back and dropped at once
            link.quick_drops += 1
            first = min(RETRY_S * 2 ** (link.quick_drops - 1), RETRY_MAX_S)
            delays = backoff(at_once=False, first=first)
        else:
            link.quick_drops = 0
            delays = backoff()
        await self._reconnect(link, delays, first=False)

    async def _reconnect(self, link: Link, delays: Iterator[float], *, first: bool) -> None:
        """Try to open ``link`` after each delay until it opens or the machine closes.

        ``first``: the link never opened (down at start-up): its origin rule is skipped
        (never applied late). Otherwise it was open and is checked for a power loss."""
        for delay in delays:
            if delay:
                await self._sleep(delay)
            if self._closed:
                return
            self.reconnect_tries += 1
            for axis in link.axes:
                axis.checking = not first
            try:
                await link.open()
            except Exception as exc:
                if not _retryable(exc):
                    log.warning("%s", exc)
                    link.mark_offline(exc)
                    return
                for axis in link.axes:
                    axis.last_error = exc
                log.debug("%s", exc)
                continue
            if self._closed:
                return
            if not await self._verify(link, first):
                continue  # it hung up at once: the try failed (logged at debug level)
            log.warning("%s: link %s is online", self.source, link.url)
            link.up_since = time.monotonic()
            if first:
                for axis in link.axes:
                    axis.skip_origin()
            await self._opened(link)
            return

    async def _verify(self, link: Link, first: bool) -> bool:
        """A link just opened answers: its power check (before the token is left again), or
        on a link that never opened a status read of each axis. False when it dropped
        again meanwhile."""
        link.verifying = True
        try:
            if not first:
                await self._check_power(link)
            else:
                for axis in link.axes:
                    try:
                        await axis.status()
                    except MachineLinkError:
                        break
                    except ServobusError as exc:  # no answer: not a link failure
                        log.debug("axis %s: first read: %s", axis.name, exc)
        finally:
            link.verifying = False
        return link.online

    async def _check_power(self, link: Link) -> None:
        """Every axis of a reopened link: a power loss meanwhile? Motion waits for it."""
        try:
            for axis in link.axes:
                try:
                    await axis.check_power()
                except MachineLinkError:
                    return  # dropped again: the next reopen checks
                except ServobusError as exc:  # no answer: flagged (check_power)
                    log.debug("axis %s: power check after reopening: %s", axis.name, exc)
        finally:
            for axis in link.axes:
                axis.checking = False

    def guard_limits(self, period: float = 0.05) -> None:
        """Watch every limited axis for motion past its limits from outside the machine API
        (GUI jog, waves) and stop it (AsyncMachineAxis.guard); until close()."""
        if self._guards:
            return
        self._guards = [asyncio.create_task(a.guard(period), name=f"limit-guard {a.name}")
                        for a in self._axes.values() if a.limits is not None]

    # ------------------------------------------------------------- every axis
    def online_cores(self) -> dict[str, AsyncAxis]:
        return {name: a.axis for name, a in self._axes.items() if a.axis is not None}

    def _check_open(self) -> None:
        if self._closed:
            raise ClosedError(f"the machine {self.name} is closed")

    async def stop_all(self, *, timeout_s: float = DEFAULT_HALT_TIMEOUT_S,
                       ) -> dict[str, BaseException | None]:
        """Stop every online axis at once (servobus.axis.halt.halt), each stop bounded by
        ``timeout_s``; None per stopped axis, the error otherwise (offline axes: their
        MachineLinkError). Never raises per axis."""
        self._check_open()
        for axis in self._axes.values():
            await axis._end_lease("stopped")
        out: dict[str, BaseException | None] = dict(
            await halt(self.online_cores(), timeout_s=timeout_s))
        for name, axis in self._axes.items():
            if name not in out:
                try:
                    axis.core()
                except Exception as exc:
                    out[name] = exc
        return {name: out[name] for name in self._axes}

    async def move_together(self, targets: Mapping[str, float], *, wait: bool = False,
                            timeout: float | None = None) -> TogetherReport:
        """Absolute moves of several axes (user units) started together.

        Every target is checked (names, limits, links online) before anything is sent.
        Axes whose Axis reports the same ``sync_group()`` start by one trigger; the rest
        start as close together as the links allow (concurrently). The report holds the
        measured start skew."""
        self._check_open()
        axes = [self[name] for name in targets]
        counts: dict[str, int] = {}
        for axis in axes:
            axis.check_target(targets[axis.name])
        for axis in axes:
            counts[axis.name] = axis.to_counts(targets[axis.name])  # offline: raises here
            axis._motion()  # a power loss not acknowledged: PowerLostError, nothing sent
        groups: dict[object, list[AsyncMachineAxis]] = {}
        singles: list[AsyncMachineAxis] = []
        for axis in axes:
            key = axis.core().sync_group()
            if key is None:
                singles.append(axis)
            else:
                groups.setdefault(key, []).append(axis)
        jobs: list[tuple[tuple[str, ...], asyncio.Future[float] | asyncio.Task[float]]] = []
        for members in groups.values():
            if len(members) == 1:
                singles.append(members[0])
        synced = [m for m in groups.values() if len(m) > 1]
        for axis in axes:
            await axis._end_lease("stopped")

        async def start_group(members: list[AsyncMachineAxis]) -> float:
            lead = members[0]
            with contextlib.ExitStack() as commanding:
                for m in members:
                    commanding.enter_context(m._commanding())
                with lead._watch():
                    await lead.core().sync_move_to([(m.core(), counts[m.name])
                                                    for m in members])
            return time.perf_counter()

        async def start_one(axis: AsyncMachineAxis) -> float:
            await axis._move(lambda core: core.move_to(counts[axis.name]))
            return time.perf_counter()

        for members in synced:
            jobs.append((tuple(m.name for m in members),
                         asyncio.ensure_future(start_group(members))))
        for axis in singles:
            jobs.append(((axis.name,), asyncio.ensure_future(start_one(axis))))
        results = await asyncio.gather(*(job for _, job in jobs), return_exceptions=True)
        starts: dict[str, float] = {}
        failure: BaseException | None = None
        for (names, _), result in zip(jobs, results, strict=True):
            if isinstance(result, BaseException):
                failure = failure or result
                continue
            for name in names:
                starts[name] = result
        if failure is not None:  # some started: stop them all, then report the failure
            await halt({n: self._axes[n].core() for n in targets if self._axes[n].online})
            raise failure
        report = TogetherReport(starts={n: starts[n] for n in targets},
                                groups=tuple(tuple(m.name for m in g) for g in synced))
        if wait:
            await asyncio.gather(*(a.wait_idle(timeout) for a in axes))
        return report

    # ------------------------------------------------------------- closing
    async def close(self, *, stop: bool = True) -> None:
        """Stop every axis first (halt), then the watchers, retries and links; idempotent.

        ``stop=False`` leaves the drives doing what they were told (a one-shot command
        such as ``servobus move`` without ``--wait`` exits while the motor moves)."""
        if self._closed:
            return
        self._closed = True
        for axis in self._axes.values():  # no target update may follow the stop
            await axis._end_lease("closed")
        try:
            if stop:
                await halt(self.online_cores())
        finally:
            tasks = [*self._retries, *self._guards]
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(BaseException):
                    await task
            for axis in self._axes.values():
                await axis._closed()
            for link in reversed(self.links):
                await link.close()

    async def __aenter__(self) -> AsyncMachine:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.close()

    def __repr__(self) -> str:
        return f"<AsyncMachine {self.name} axes {', '.join(self._axes)}>"


async def _close(cores: Sequence[AsyncAxis]) -> None:
    for core in reversed(cores):  # siblings first, the owner last
        with contextlib.suppress(Exception):
            await core.close()


def _retryable(exc: BaseException) -> bool:
    """A link that failed to open may come later; a mistake in the file will not, nor a
    rule the drive cannot follow (``origin = "home"`` where the family has no homing:
    NotSupported, never reported as a link problem)."""
    return not isinstance(exc, ArgumentRangeError | LimitError | NotSupported)


async def open_machine_async(path: str | Path | None = None, *, retry: bool = False,
                             only: Collection[str] | None = None, origins: bool = True,
                             sleep: Sleep = asyncio.sleep) -> AsyncMachine:
    """Open the machine file ``path`` (None: the built-in virtual machine).

    ``only``: open just the links of these axes (the others stay offline, never opened);
    the CLI opens only the axis a command acts on. ``origins=False``: apply no origin rule
    (the one-shot CLI commands; module docstring). ``sleep``: the reconnect clock (module
    docstring)."""
    if path is None:
        spec, source = builtin_spec(), BUILTIN_SOURCE
    else:
        spec = load_machine_file(path)
        source = str(path)
    machine = AsyncMachine(spec, source=source, sleep=sleep)
    await machine._open(retry, only, origins)
    return machine


async def open_url_machine_async(url: str, drive_ids: Sequence[int | None] = (None,), *,
                                 retry: bool = False,
                                 sleep: Sleep = asyncio.sleep) -> AsyncMachine:
    """A bare drive URL as a machine of one axis per id (config.url_spec): the GUI, the CLI
    and the gateway run motion, limits and leases through the one machine path."""
    spec = url_spec(url, drive_ids)
    machine = AsyncMachine(spec, source=url, sleep=sleep)
    await machine._open(retry, None)
    return machine
