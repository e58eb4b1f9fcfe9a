"""AsyncMachine: every axis of a machine file, by name, in user units (docs/machine.md).

``open_machine_async(path)`` reads the file, opens each link once and applies the origin
rules. ``retry=False`` (scripts, the CLI): a link that cannot be opened is one
MachineLinkError naming the axis and its URL, and whatever was opened is closed again.
``retry=True`` (GUI, gateway): such an axis starts offline (``online`` False,
``last_error`` set) and a background task retries its link every :data:`RETRY_S` (doubling up
to :data:`RETRY_MAX_S`) until it opens or the machine closes.

``close()`` stops every axis first (servobus.axis.halt.halt), then closes the links.

Origin rules (``origin = "set"`` / ``"home"``; decision, issue 28): a rule is applied once per
machine, when its axis's link first opens; reopening a link never applies it again.
``origins=False`` applies none: the one-shot CLI commands open the machine that way, since a
command cannot know whether the drive was power-cycled since the last one. Applying the rule
at every command re-zeroed the axis where it stood each time (two ``move 90deg`` turned 180
deg and ``position`` read 0 after each), and on a DYN5 setting the origin resets the drive's
servo control. Long-running owners (GUI, gateway, a script) open with origins applied.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, TracebackType

from servobus.axis.base import AsyncAxis
from servobus.axis.halt import halt
from servobus.errors import ArgumentRangeError, LimitError
from servobus.machine.axis import AsyncMachineAxis
from servobus.machine.builtin import BUILTIN_SOURCE, builtin_spec
from servobus.machine.config import MachineSpec, load_machine_file, url_spec
from servobus.machine.links import Link, group_links

log = logging.getLogger(__name__)

RETRY_S = 0.5
RETRY_MAX_S = 5.0


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

    def __init__(self, spec: MachineSpec, *, source: str) -> None:
        self.spec = spec
        self.source = source
        self._axes = {s.name: AsyncMachineAxis(s, source) for s in spec.axes}
        self.links = group_links(list(self._axes.values()), source)
        self._retries: list[asyncio.Task[None]] = []
        self._guards: list[asyncio.Task[None]] = []
        self._closed = False
        self._origins = True
        self._origin_done: set[str] = set()  # axes whose origin rule ran (never again)

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
            except Exception as exc:
                if not retry or not _retryable(exc):
                    await self.close()
                    raise
                link.mark_offline(exc)
                log.warning("%s", exc)
                self._retries.append(asyncio.create_task(self._retry(link),
                                                         name=f"machine-retry {link.url}"))

    async def _apply_origins(self, link: Link) -> None:
        """Each axis's origin rule, once per machine (module docstring)."""
        if not self._origins:
            return
        for axis in link.axes:
            if axis.name in self._origin_done:
                continue
            await axis.apply_origin()
            self._origin_done.add(axis.name)

    async def _retry(self, link: Link) -> None:
        delay = RETRY_S
        while not self._closed:
            await asyncio.sleep(delay)
            try:
                await link.open()
                await self._apply_origins(link)
            except Exception as exc:
                link.mark_offline(exc)
                delay = min(delay * 2, RETRY_MAX_S)
                continue
            log.warning("%s: link %s is online", self.source, link.url)
            return

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

    async def stop_all(self) -> dict[str, BaseException | None]:
        """Stop every online axis at once (servobus.axis.halt.halt); None per stopped axis,
        the error otherwise (offline axes: their MachineLinkError). Never raises per axis."""
        for axis in self._axes.values():
            await axis._end_lease("stopped")
        out: dict[str, BaseException | None] = dict(await halt(self.online_cores()))
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
        axes = [self[name] for name in targets]
        counts: dict[str, int] = {}
        for axis in axes:
            axis.check_target(targets[axis.name])
        for axis in axes:
            counts[axis.name] = axis.to_counts(targets[axis.name])  # offline: raises here
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
            lead = members[0].core()
            await lead.sync_move_to([(m.core(), counts[m.name]) for m in members])
            return time.perf_counter()

        async def start_one(axis: AsyncMachineAxis) -> float:
            await axis.core().move_to(counts[axis.name])
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
            for task in [*self._retries, *self._guards]:
                task.cancel()
            for task in [*self._retries, *self._guards]:
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


def _retryable(exc: BaseException) -> bool:
    """A link that failed to open may come later; a mistake in the file will not."""
    return not isinstance(exc, ArgumentRangeError | LimitError)


async def open_machine_async(path: str | Path | None = None, *, retry: bool = False,
                             only: Collection[str] | None = None,
                             origins: bool = True) -> AsyncMachine:
    """Open the machine file ``path`` (None: the built-in virtual machine).

    ``only``: open just the links of these axes (the others stay offline, never opened);
    the CLI opens only the axis a command acts on. ``origins=False``: apply no origin rule
    (the one-shot CLI commands; module docstring)."""
    if path is None:
        spec, source = builtin_spec(), BUILTIN_SOURCE
    else:
        spec = load_machine_file(path)
        source = str(path)
    machine = AsyncMachine(spec, source=source)
    await machine._open(retry, only, origins)
    return machine


async def open_url_machine_async(url: str, drive_ids: Sequence[int | None] = (None,), *,
                                 retry: bool = False) -> AsyncMachine:
    """A bare drive URL as a machine of one axis per id (config.url_spec): the GUI, the CLI
    and the gateway run motion, limits and leases through the one machine path."""
    spec = url_spec(url, drive_ids)
    machine = AsyncMachine(spec, source=url)
    await machine._open(retry, None)
    return machine
