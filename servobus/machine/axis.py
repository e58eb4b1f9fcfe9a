"""AsyncMachineAxis: one named axis of a machine, in its user unit, inside its soft limits.

Every motion is checked against the limits before anything reaches the wire
(:class:`servobus.errors.LimitError`). Decisions (docs/machine.md):

* ``move_to`` needs no read: the target is checked and converted, then sent. ``move_by``
  reads the position first (a read, no motion) unless the distance alone is longer than the
  travel; a refused relative move sends no motion command.
* ``jog(v)`` and ``turn(v)`` (constant speed, user units per second) are leases
  (servobus.machine.lease): position targets streamed a bounded lead ahead of the motor,
  never past the limit they head for, ending by themselves ``ttl`` seconds after the last
  call. At or past that limit they are refused ("at soft limit"). Only a ``continuous``
  axis (no limits) turns open-ended. docs/safety.md.
* Limits count from the drive's origin: before an origin is set (``origin = "set"`` in the
  file, or ``set_origin()``) they are relative to wherever the drive counts from (power-on
  position, or a multi-turn encoder's zero).
* While the link is offline every call raises :class:`MachineLinkError` naming the axis and
  URL; ``limits``, ``unit`` and the checks still work.
* Recovery (issue 29, docs/machine.md "Recovery"): a call whose link is lost (ConnectionLost)
  raises MachineLinkError and tells the machine, which takes every axis of that link
  offline and reopens it. ``last_good`` keeps the time of the last call that succeeded.
  Nothing is resumed: a motion that ran is reported in ``interrupted``, its lease ends.
  A drive that may have lost power is flagged (``power_lost``) until :meth:`acknowledge`;
  until then motion commands raise PowerLostError (stop, enable, reset ... still work).
* Motion seen to end (docs/machine.md, "Power loss"): a motion runs from the moment its
  command is counted until a stop, a waited move's return, or a status read that says the
  drive stands; a status read that sees the drive moving (whoever moved it) marks one as
  running. Only a read begun after the last motion command or stop returned, and answered
  before the next one started, counts: a read under way meanwhile may have reached the
  drive before the command did. (Decision, a red CI run of the GUI's recovery test: a
  poll begun while the first move read GEAR_NUM answered "not moving", and a drive
  restarted just after the move, near its start, came back unflagged.)
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Awaitable, Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING

from servobus.axis.capabilities import Capability
from servobus.errors import (
    ArgumentRangeError,
    ClosedError,
    ConnectionLost,
    DriveTimeout,
    LimitError,
    MachineLinkError,
    NotSupported,
    OwnerError,
    PowerLostError,
    ServobusError,
)
from servobus.machine.config import AxisSpec
from servobus.machine.lease import DEFAULT_TTL_S, Lease, check_speed, check_ttl, stream
from servobus.machine.units import Scale

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis
    from servobus.axis.types import AxisStatus, Family
    from servobus.link.stats import StreamStats
    from servobus.tune.tuner import Trial, TuneResult

log = logging.getLogger(__name__)

UNITS_PER_S = {"mm": "mm/s", "deg": "deg/s", "rev": "rev/s", "counts": "counts/s"}

#: Calls in a row that time out, over at least SILENT_S, before a drive counts as silent;
#: when a silent drive answers again it may have been power-cycled (flagged,
#: docs/machine.md). Decision: the seconds keep a loaded host, whose replies miss a few
#: deadlines in a row, from flagging a drive that never lost power (a DMM drive takes well
#: over SILENT_S to boot).
SILENT_CALLS = 3
SILENT_S = 2.0
#: What the machine leaves in a drive's power-cleared cell (AsyncAxis.power_marker; DYN5
#: memory test instance 0x01, range 0..63).
POWER_TOKEN = 0x29
#: Without such a cell: a position that moved by more than 1/64 rev while the link was down
#: and no motion ran counts as a power loss.
JUMP_REVS = 1 / 64

DropHandler = Callable[["AsyncMachineAxis", BaseException], None]


class AsyncMachineAxis:
    """One axis of a machine file; see the module docstring for the rules."""

    def __init__(self, spec: AxisSpec, source: str = "") -> None:
        self.spec = spec
        self.source = source  # the file, for messages
        self.axis: AsyncAxis | None = None  # the underlying Axis; None while offline
        self.last_error: BaseException | None = None
        self._lease: Lease | None = None
        #: Set by the machine: told when a call finds the link lost.
        self.on_drop: DropHandler | None = None
        self._last_good: float | None = None
        self._last_counts: int | None = None
        #: The last position read before the link dropped, kept for the power check until it
        #: ran (reads on the reopened link - a GUI's poll - must not replace it first).
        self._counts_at_drop: int | None = None
        #: A motion runs, not yet seen to end (why, for ``interrupted``); None: none known.
        self._moving: str | None = None
        #: Bumped when a motion command (or a stop) starts and when it returns: a status
        #: read applies (``_seen``) only if no command started or returned while it was
        #: under way (module docstring, "Motion seen to end").
        self._epoch = 0
        self._silent = 0  # calls in a row that timed out
        self._silent_since = 0.0  # time.monotonic() of the first of them
        self._interrupted: str | None = None
        self._power_lost: str | None = None
        #: The tuning run on this axis: its owner and the task it runs in (Stop cancels it).
        self._tuning: tuple[str, asyncio.Task[object] | None] | None = None
        self._origin_pending = False
        self._is_closed = False
        self.checking = False  # set by the machine while it checks a reopened link
        self.marker_before: int | None = None  # the power cell when the link last opened
        self._profile_for: AsyncAxis | None = None  # the Axis apply_profile() ran on

    # ------------------------------------------------------------- identity
    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def unit(self) -> str:
        return self.spec.unit

    @property
    def speed_unit(self) -> str:
        return UNITS_PER_S[self.spec.unit]

    @property
    def limits(self) -> tuple[float, float] | None:
        return self.spec.limits

    @property
    def url(self) -> str:
        return self.spec.url

    @property
    def drive_id(self) -> int | None:
        """The id in the file; once online the Axis's (the protocol's default filled in)."""
        return self.axis.drive_id if self.axis is not None else self.spec.drive_id

    @property
    def online(self) -> bool:
        return self.axis is not None

    @property
    def family(self) -> Family | None:
        return self.axis.family if self.axis is not None else None

    @property
    def protocol(self) -> str | None:
        return self.axis.protocol if self.axis is not None else None

    @property
    def default_speed(self) -> float | None:
        """``speed`` of the file, user units per second (turn's and the GUI jog's default)."""
        return self.spec.speed

    @property
    def continuous(self) -> bool:
        """The axis may turn for ever (``continuous = true``): constant speed is open-ended."""
        return self.spec.continuous

    def core(self) -> AsyncAxis:
        """The underlying Axis, or MachineLinkError naming the axis and its URL."""
        if self._is_closed:
            raise ClosedError(f"axis {self.name}: the machine is closed")
        if self.axis is None:
            why = f": {self.last_error}" if self.last_error is not None else ""
            raise MachineLinkError(f"axis {self.name} is offline ({self.url}){why}")
        return self.axis

    # ------------------------------------------------------------- recovery (issue 29)
    @property
    def last_good(self) -> float | None:
        """``time.time()`` of the last call that succeeded on this axis (None: none yet)."""
        return self._last_good

    @property
    def interrupted(self) -> str | None:
        """The motion that ran when the link dropped (never re-sent), until the next motion
        command or :meth:`acknowledge`; None otherwise."""
        return self._interrupted

    @property
    def power_lost(self) -> bool:
        """The drive may have lost power (its position or origin may be gone): motion is
        refused (PowerLostError) until :meth:`acknowledge`."""
        return self._power_lost is not None

    @property
    def power_lost_reason(self) -> str | None:
        """How servobus noticed the power loss (docs/machine.md), None when not flagged."""
        return self._power_lost

    @property
    def origin_pending(self) -> bool:
        """The file's ``origin`` was not applied: the link opened only after start-up
        (reopening never applies it); :meth:`set_origin` clears it."""
        return self._origin_pending

    async def acknowledge(self) -> None:
        """A person or program has seen the power loss (and the interrupted motion): the
        flags clear and motion is allowed again. Nothing is sent. Refused
        (MachineLinkError) while a reopened link is being checked for a power loss: the
        check may still flag what the caller has not seen."""
        if self.checking:
            raise MachineLinkError(f"axis {self.name}: its link is back and being checked for "
                                   "a power loss; nothing was acknowledged, try again")
        if self._power_lost is not None or self._interrupted is not None:
            log.warning("axis %s: acknowledged (%s)", self.name,
                        self._power_lost or self._interrupted)
        self._power_lost = None
        self._interrupted = None

    def flag_power_lost(self, why: str) -> None:
        """Flag a possible power loss (the machine's checks; one log line)."""
        if self._power_lost is None:
            log.warning("axis %s: the drive may have lost power (%s); acknowledge() it "
                        "before the next motion", self.name, why)
        self._power_lost = why

    @contextlib.contextmanager
    def _watch(self) -> Iterator[None]:
        """Around every call on the Axis: a lost link becomes MachineLinkError (and the
        machine hears of it), timeouts are counted, success stamps ``last_good``."""
        used = self.axis
        try:
            yield
        except MachineLinkError:
            raise
        except ConnectionLost as exc:
            raise self.link_lost(exc, used) from exc
        except DriveTimeout:
            if not self._silent:
                self._silent_since = time.monotonic()
            self._silent += 1
            raise
        self._good()

    def _good(self) -> None:
        self._last_good = time.time()
        if self._silent >= SILENT_CALLS and time.monotonic() - self._silent_since >= SILENT_S:
            self.flag_power_lost(f"it did not answer {self._silent} calls in a row and "
                                 "answers again")
        self._silent = 0

    def link_lost(self, exc: BaseException, used: AsyncAxis | None) -> MachineLinkError:
        """The error a call on a lost link raises; the machine takes the link offline
        (unless ``used``, the Axis the call ran on, is no longer this axis's: the link was
        reopened meanwhile)."""
        err = MachineLinkError(f"axis {self.name}: the link {self.url} is down: {exc}")
        if used is not None and used is self.axis and self.on_drop is not None:
            self.on_drop(self, err)
        return err

    def went_offline(self, err: BaseException) -> None:
        """The link dropped (the machine calls this for every axis on it): nothing is
        resumed; a motion that ran is reported in ``interrupted``, a lease ends."""
        self.axis = None
        self.last_error = err
        if self._counts_at_drop is None:  # a link that drops again before its check keeps it
            self._counts_at_drop = self._last_counts
        lease = self._lease
        running = lease is not None and lease.alive
        interrupted = None
        if running and lease is not None:
            lease.ended = "link dropped"
            if lease.task is not None and lease.task is not asyncio.current_task():
                lease.task.cancel()  # its own task ends by itself on the failed read
            interrupted = f"the {lease.owner} motion at {lease.speed:g} " \
                          f"{self.speed_unit} (lease) stopped being sent"
        elif self._moving is not None:
            interrupted = self._moving
        self._moving = None
        if interrupted is not None:  # one line when it happens, not at every later drop
            self._interrupted = interrupted
            log.warning("axis %s: motion interrupted by the link drop: %s; it is not "
                        "re-sent", self.name, interrupted)

    async def mark_power(self) -> None:
        """Leave the machine's token in the drive's power-cleared cell, where it has one;
        what the cell held before is kept in ``marker_before`` (``servobus ack`` reports
        it: the token means no power cycle since a machine last left it)."""
        core = self.core()
        with self._watch():
            self.marker_before = await core.power_marker()
            if self.marker_before is not None:
                await core.power_marker(POWER_TOKEN)

    async def check_power(self) -> None:
        """After the link came back: did the drive lose power meanwhile? The cell where
        the family has one (DYN5), else the position (docs/machine.md). A check the drive
        does not answer (a timeout, an error; not a dropped link) cannot tell: the axis is
        flagged, its position unverified, and the error raised. (Decision, issue 29's fault
        run: a check that timed out on a loaded host let a drive restart pass unflagged,
        and its stale reference flagged the next, harmless drop.)"""
        core = self.core()
        try:
            await self._check_power(core)
        except MachineLinkError:
            raise  # dropped again: the next reopen checks
        except ServobusError as exc:
            self._counts_at_drop = None
            self.flag_power_lost(f"the check after the link came back got no answer ({exc}): "
                                 "the position is unverified")
            raise

    async def _check_power(self, core: AsyncAxis) -> None:
        with self._watch():
            marker = await core.power_marker()
        if marker is not None:
            if marker != POWER_TOKEN:
                self.flag_power_lost(f"its power-cleared memory holds {marker}, not the "
                                     f"token {POWER_TOKEN} left there: power cycle or Reset")
            with self._watch():
                await core.power_marker(POWER_TOKEN)
            self._counts_at_drop = None
            return
        with self._watch():
            counts = await core.position()  # read either way: it proves the link answers
        before, self._counts_at_drop = self._counts_at_drop, None
        self._seen(counts)
        if self._interrupted is not None:
            self.flag_power_lost("a motion was interrupted and the family keeps no mark "
                                 "of a power cycle: the position is unverified")
            return
        if before is not None and abs(counts - before) > core.counts_per_rev * JUMP_REVS:
            self.flag_power_lost(f"the position moved from {before} to {counts} counts "
                                 "while the link was down")

    def _motion(self) -> AsyncAxis:
        """The Axis for a motion command: refused while a power loss is unacknowledged."""
        if self._power_lost is not None:
            raise PowerLostError(f"axis {self.name}: the drive may have lost power "
                                 f"({self._power_lost}); acknowledge it first "
                                 "(acknowledge(), servobus ack); nothing was sent")
        core = self.core()
        if self.checking:
            raise MachineLinkError(f"axis {self.name}: its link is back and being checked for "
                                   "a power loss; nothing was sent, try again")
        if self._tuning is not None:
            raise OwnerError(f"axis {self.name} is being tuned by {self._tuning[0]}; Stop "
                             "ends the run, nothing was sent", owner=self._tuning[0])
        self._interrupted = None
        return core

    def _seen(self, counts: int | None = None, status: AxisStatus | None = None,
              since: int | None = None) -> None:
        """A read's result; ``since``: ``_epoch`` when the read began. A status read under
        way while a motion command (or a stop) started or returned (a front end polls while
        it moves the axis) says nothing of that command: it may have reached the drive
        before the command did (a DMM axis's first move reads GEAR_NUM before it sends),
        so its "not moving" must not end the motion, or a drop right after the command
        would not count as an interrupted motion. A read that applies and sees the drive
        moving marks a motion as running, whoever started it (a wave, another program)."""
        if counts is not None:
            self._last_counts = counts
        if status is None or since != self._epoch:
            return
        if not status.moving:
            self._moving = None
        elif self._moving is None:
            self._moving = "the drive was seen moving and not yet seen to stop"

    @contextlib.contextmanager
    def _commanding(self, moves: bool = True) -> Iterator[None]:
        """Around a motion command (``moves``) or a stop, from before it is sent until it
        returns: reads under way meanwhile are not applied (``_seen``)."""
        self._epoch += 1
        if moves:
            self._moving = "a commanded motion may not have finished"
        try:
            yield
        finally:
            self._epoch += 1

    @property
    def scale(self) -> Scale:
        s = self.spec
        return Scale(unit=s.unit, counts_per_rev=self.core().counts_per_rev, per_rev=s.per_rev,
                     gear=s.gear, direction=s.direction)

    # ------------------------------------------------------------- units and limits
    def to_counts(self, user: float) -> int:
        return self.scale.to_counts(user)

    def to_user(self, counts: float) -> float:
        return self.scale.to_user(counts)

    def check_target(self, target: float) -> float:
        """``target`` (user units) inside the limits, else LimitError; nothing is sent."""
        if isinstance(target, bool) or not isinstance(target, int | float) \
                or not math.isfinite(target):
            raise ArgumentRangeError(f"axis {self.name}: a target must be a finite number "
                                     f"of {self.unit}, got {target!r}")
        if self.limits is not None:
            low, high = self.limits
            if not low <= target <= high:
                raise LimitError(f"axis {self.name}: {target:g} {self.unit} is outside the "
                                 f"soft limits [{low:g}, {high:g}] {self.unit}; nothing was sent")
        return float(target)

    # ------------------------------------------------------------- reads (user units)
    async def counts(self) -> int:
        """The position in the Axis's counts."""
        with self._watch():
            counts = await self.core().position()
        self._seen(counts)
        return counts

    async def position(self) -> float:
        return self.to_user(await self.counts())

    async def speed(self) -> float:
        """User units per second (the Axis reads motor rpm)."""
        with self._watch():
            return self.scale.from_rpm(await self.core().speed())

    async def status(self) -> AxisStatus:
        since = self._epoch
        with self._watch():
            status = await self.core().status()
        self._seen(status=status, since=since)
        return status

    async def readings(self) -> tuple[float, float, AxisStatus]:
        """Position and speed in user units and the status (see ``AsyncAxis.readings``)."""
        since = self._epoch
        with self._watch():
            position, speed, status = await self.core().readings()
        self._seen(position, status, since)
        return self.to_user(position), self.scale.from_rpm(speed), status

    async def current(self) -> float:
        """The motor current, A (AsyncAxis.current)."""
        with self._watch():
            return await self.core().current()

    async def following_error(self) -> float | None:
        """Commanded minus actual position in user units as the drive reports it, None
        where it reports none (AsyncAxis.following_error)."""
        with self._watch():
            counts = await self.core().following_error()
        return None if counts is None else self.to_user(counts)

    # ------------------------------------------------------------- motion
    async def stream_target(self, target: float, speed: float) -> None:
        """One target update of a position stream from outside (``servobus hal``: LinuxCNC's
        position command): ``target`` user units, checked against the limits, run by the
        drive's own target update (AsyncAxis.stream_to, Capability.STREAM_TARGETS) at
        ``speed`` user units per second (the cruise speed where the family takes one).
        Sent once, never re-sent. The caller owns the stream's safety (its own speed and
        acceleration checks, a stop when its feed stops): unlike :meth:`jog` nothing here
        ends by itself but the drive, which rests at the last target."""
        self.check_target(target)
        core = self._motion()
        core.require(Capability.STREAM_TARGETS)
        self.check_owner("stream")
        counts = self.to_counts(target)
        rpm = abs(self.scale.to_rpm(speed))
        with self._commanding(), self._watch():
            await core.stream_to(counts, rpm)

    async def stream_cycles(self, next_target: Callable[[], float | None]) -> StreamStats:
        """Cyclic synchronous position (AsyncAxis.stream_cycles, Capability.CYCLIC_POSITION):
        every cycle of the drive, ``next_target()`` in user units, checked against the
        limits (LimitError ends the stream, the drive resting at the last position), until
        it returns None. As :meth:`stream_target`, the caller owns the stream's safety."""
        core = self._motion()
        core.require(Capability.CYCLIC_POSITION)
        self.check_owner("stream")
        next_position = self._counts_of(next_target)
        with self._commanding(), self._watch():
            return await core.stream_cycles(next_position)

    def cyclic_group(self) -> object | None:
        """The key of the axes this axis streams cyclic positions with as one group
        (Capability.CYCLIC_GROUP: one cycle and one synchronisation signal for all, e.g.
        the motors of one EasyCan bus); None where it has none or its link is down."""
        core = self.axis
        if core is None or not core.supports(Capability.CYCLIC_GROUP):
            return None
        return core.sync_group()

    async def stream_cycles_together(
            self, streams: Sequence[tuple[AsyncMachineAxis, Callable[[], float | None]]],
    ) -> StreamStats:
        """Cyclic synchronous position of several axes of one :meth:`cyclic_group` as one
        stream (AsyncAxis.stream_cycles_together): every cycle each ``next_target()`` in its
        axis's user units, checked against its limits; the stream ends for all when any
        returns None or is refused, every drive resting at its last position. As
        :meth:`stream_target`, the caller owns the stream's safety."""
        cores: list[tuple[AsyncAxis, Callable[[], int | None]]] = []
        for axis, next_target in streams:
            core = axis._motion()
            core.require(Capability.CYCLIC_GROUP)
            axis.check_owner("stream")
            cores.append((core, axis._counts_of(next_target)))
        with contextlib.ExitStack() as commanding:
            for axis, _ in streams:
                commanding.enter_context(axis._commanding())
            with self._watch():
                return await self._motion().stream_cycles_together(cores)

    def _counts_of(self, next_target: Callable[[], float | None],
                   ) -> Callable[[], int | None]:
        """``next_target`` (user units) as counts, each checked against the limits."""
        def next_position() -> int | None:
            target = next_target()
            if target is None:
                return None
            return self.to_counts(self.check_target(target))
        return next_position

    async def move_to(self, target: float, *, wait: bool = False,
                      timeout: float | None = None) -> None:
        """Absolute move to ``target`` user units (checked against the limits first)."""
        self.check_target(target)
        counts = self.to_counts(target)
        await self._end_lease("replaced by a move")
        await self._move(lambda core: core.move_to(counts, wait=wait, timeout=timeout), wait)

    async def move_by(self, distance: float, *, wait: bool = False,
                      timeout: float | None = None) -> None:
        """Relative move by ``distance`` user units; the end point is checked first."""
        if isinstance(distance, bool) or not isinstance(distance, int | float) \
                or not math.isfinite(distance):
            raise ArgumentRangeError(f"axis {self.name}: a distance must be a finite "
                                     f"number of {self.unit}, got {distance!r}")
        if self.limits is not None:
            low, high = self.limits
            if abs(distance) > high - low:
                raise LimitError(f"axis {self.name}: {distance:g} {self.unit} is longer than "
                                 f"the travel [{low:g}, {high:g}]; nothing was sent")
            self.check_target(await self.position() + distance)
        counts = self.to_counts(distance)
        await self._end_lease("replaced by a move")
        await self._move(lambda core: core.move_by(counts, wait=wait, timeout=timeout), wait)

    async def _move(self, send: Callable[[AsyncAxis], Awaitable[None]],
                    waited: bool = False) -> None:
        """A motion command, sent once (never re-sent, whatever happens to the link);
        ``waited``: ``send`` returns once the motion ended (a later drop interrupts nothing)."""
        core = self._motion()
        with self._commanding(), self._watch():
            await send(core)
            if waited:
                self._moving = None

    async def turn(self, speed: float | None = None, *, owner: str = "api",
                   ttl: float = DEFAULT_TTL_S) -> None:
        """Constant speed in user units per second (None: the file's ``speed``; 0 stops).

        On a ``continuous`` axis an open-ended speed command. On any other axis a lease
        (:meth:`jog`): it ends ``ttl`` seconds after the last call unless called again."""
        if self.spec.continuous:  # the link gives its Axis the spec's (links.Link.open)
            speed = self._checked_speed(speed)
            rpm = round(self.scale.to_rpm(speed))
            await self._end_lease("replaced by an open-ended speed")
            await self._move(lambda core: core.turn(rpm))
            return
        await self.jog(speed, owner=owner, ttl=ttl)

    async def jog(self, speed: float | None = None, *, owner: str = "api",
                  ttl: float = DEFAULT_TTL_S) -> None:
        """Start or renew a leased motion at ``speed`` user units per second, held by
        ``owner`` (a page, a session, a program), ending ``ttl`` seconds (at most 1) after
        the last call (servobus.machine.lease, docs/safety.md). 0 releases it.

        Refused (nothing sent): heading out at or past a soft limit (LimitError "at soft
        limit"), above the drive's own top speed, or while another owner holds the axis
        (OwnerError). The target never passes the limit it heads for."""
        speed = self._checked_speed(speed)
        ttl = check_ttl(ttl)
        self.check_owner(owner)
        lease = self.lease
        if speed == 0:
            if lease is not None:
                await self.stop()
            return
        heading = 1 if speed > 0 else -1
        if lease is not None and lease.heading == heading:
            if lease.profile is not None and speed != lease.speed:
                check_speed(self.name, speed, self.scale.to_rpm(speed), lease.profile,
                            self.speed_unit, self.scale.from_rpm)
            lease.speed = speed  # the streamer picks the new speed up at its next update
            lease.renew(ttl)
            return
        core = self._motion()
        rpm = self.scale.to_rpm(speed)
        with self._watch():
            profile = await core.stream_profile()
        check_speed(self.name, speed, rpm, profile, self.speed_unit, self.scale.from_rpm)
        limit = None
        if self.limits is not None:
            position = await self.position()
            limit = self.limits[1] if heading > 0 else self.limits[0]
            if heading * (position - limit) >= -self._at_limit_tolerance():
                raise LimitError(f"axis {self.name} is at {position:g} {self.unit}, at soft "
                                 f"limit {limit:g} {self.unit}; moving further out is "
                                 "refused, nothing was sent")
        await self._end_lease("reversed")
        accel = abs(self.scale.from_rpm(profile.accel_rpm_s))
        new = Lease(owner, speed, accel, limit, time.monotonic() + ttl, profile=profile)
        new.task = asyncio.create_task(self._stream(new), name=f"lease {self.name}")
        self._lease = new

    async def tune(self, distance: int, *, owner: str = "api",
                   vibration_limit: float | None = None, trace: bool = True,
                   save: bool = False, goal: str = "settling",
                   on_trial: Callable[[Trial], None] | None = None) -> TuneResult:
        """The manuals' tuning procedure (servobus.tune, docs/tuning.md): test moves between
        here and ``distance`` counts away, inside the soft limits (checked before anything
        moves); the kept gains come back on an abort, a failure or a cancel. Refused while
        another owner's lease or tuning run holds the axis; while it runs, other motion is
        refused and :meth:`stop` cancels it (Stop always wins). ``trace=False`` polls where
        a trace exists; ``save`` keeps the gains where the family saves with a command;
        ``goal`` "settling" (default) or "stiffness" (servobus.tune.tuner.GOALS). Takes
        seconds."""
        from servobus.tune import kept
        from servobus.tune.axis_plant import AxisPlant
        from servobus.tune.tuner import ABORT_VIBRATION, Limits, Tuner

        self.check_owner(owner)
        if self._tuning is not None:
            raise OwnerError(f"axis {self.name} is being tuned by {self._tuning[0]}; one "
                             "run at a time", owner=self._tuning[0])
        core = self._motion()
        here = await self.counts()
        soft = None
        if self.limits is not None:
            soft = (min(map(self.to_counts, self.limits)), max(map(self.to_counts, self.limits)))
        self.check_target(self.to_user(here + distance))  # LimitError: nothing moved
        limit = ABORT_VIBRATION if vibration_limit is None else vibration_limit
        limits = Limits(distance, soft, limit, to_user=self.to_user, unit=self.unit)
        record = kept.record_for(self.spec.url, core.drive_id, f"axis {self.name}")
        if record is not None:
            record.check_free()  # another process's run, or a killed one's gains: refused
        tuner = Tuner(AxisPlant(core, trace=trace), limits, core.counts_per_rev,
                      on_trial=on_trial, save=save, goal=goal,
                      on_kept=None if record is None else record.write)
        self._tuning = (owner, asyncio.current_task())
        try:
            with self._commanding(), self._watch():
                result = await tuner.run()
        except BaseException:
            # the record goes once the drive holds the kept gains again (the abort wrote
            # them back, or nothing was written); a failed write back leaves it for --restore
            if record is not None and tuner.written == tuner.original:
                record.remove()
            raise
        finally:
            self._tuning = None
        if record is not None:
            record.remove()  # the tuned gains are what the run meant to leave
        return result

    async def restore_gains(self) -> dict[str, int]:
        """The kept gains of a tuning run that was killed before it could write them back
        (servobus.tune.kept), each written where the drive holds another value; the record
        goes once they are back. Returns what was written. ServobusError when no run is
        recorded (an in-process virtual drive never is), OwnerError while it still runs."""
        from servobus.tune import kept

        record = kept.record_for(self.spec.url, self.core().drive_id, f"axis {self.name}")
        if record is None:
            raise ServobusError(f"axis {self.name}: an in-process virtual drive ends with "
                                "its process: no tuning run is recorded for it")
        written = await self.revert_gains(record.take())
        record.drop()
        return written

    @property
    def tuning_owner(self) -> str | None:
        """Who runs a tuning run on this axis now, or None."""
        return self._tuning[0] if self._tuning is not None else None

    async def revert_gains(self, original: Mapping[str, int]) -> dict[str, int]:
        """A tuning run's kept gains (``TuneResult.original``) back, each written only
        where the drive holds another value now; returns what was written."""
        if self._tuning is not None:
            raise OwnerError(f"axis {self.name} is being tuned by {self._tuning[0]}; the "
                             "run reverts by itself when stopped", owner=self._tuning[0])
        core = self.core()
        written: dict[str, int] = {}
        for name, value in original.items():
            with self._watch():
                if await core.read_param(name) != value:
                    await core.write_param(name, value)
                    written[name] = value
        return written

    def check_owner(self, owner: str) -> None:
        """OwnerError (nothing sent) when another owner's lease runs on this axis."""
        lease = self.lease
        if lease is not None and lease.owner != owner:
            raise OwnerError(f"axis {self.name} is held by {lease.owner}; stop it first "
                             "(Stop and STOP ALL always win)", owner=lease.owner)
        tuning = self.tuning_owner
        if tuning is not None and tuning != owner:
            raise OwnerError(f"axis {self.name} is being tuned by {tuning}; stop it first "
                             "(Stop and STOP ALL always win)", owner=tuning)

    def _checked_speed(self, speed: float | None) -> float:
        if speed is None:
            speed = self.spec.speed
            if speed is None:
                raise ArgumentRangeError(f"axis {self.name}: give a speed in "
                                         f"{self.speed_unit} (the machine file sets no "
                                         "default speed)")
        if isinstance(speed, bool) or not isinstance(speed, int | float) \
                or not math.isfinite(speed):
            raise ArgumentRangeError(f"axis {self.name}: a speed must be a finite number "
                                     f"of {self.speed_unit}, got {speed!r}")
        return float(speed)

    def _at_limit_tolerance(self) -> float:
        """How near a limit counts as at it: 1/1024 rev of the motor in user units."""
        return abs(self.to_user(self.core().counts_per_rev / 1024))

    async def _stream(self, lease: Lease) -> None:
        core = self.core()

        async def read() -> float:
            with self._watch():
                counts = await core.position()
            self._seen(counts)
            return self.to_user(counts)

        async def send(target: float) -> None:
            with self._commanding(), self._watch():
                await core.stream_to(self.to_counts(target), abs(self.scale.to_rpm(lease.speed)))

        await stream(lease, self.name, read, send, core.stop)

    @property
    def lease(self) -> Lease | None:
        """The leased motion that runs now (its owner, speed, ``at_limit``), or None."""
        lease = self._lease
        return lease if lease is not None and lease.alive else None

    def renew(self, owner: str, ttl: float = DEFAULT_TTL_S) -> bool:
        """Keep ``owner``'s running lease alive for ``ttl`` more seconds; False (and nothing
        started) when it has ended meanwhile: a renewal never resumes a motion (a CLI that
        holds a speed calls this, not :meth:`jog`, so a late renewal cannot restart it)."""
        ttl = check_ttl(ttl)
        lease = self.lease
        if lease is None or lease.owner != owner:
            return False
        lease.renew(ttl)
        return True

    async def release(self, owner: str) -> None:
        """``owner`` lets go (a page left, a session closed): its motion stops."""
        lease = self.lease
        if lease is not None and lease.owner == owner:
            await self.stop()

    async def guard(self, period: float = 0.05) -> None:
        """Watch for any motion (GUI jog, waves) beyond the limits and stop it; runs until
        cancelled. Stops an axis outside its limits whose speed points further out."""
        if self.limits is None:
            return
        low, high = self.limits
        while True:
            core = self.axis
            if core is not None:
                try:
                    position = await self.position()
                    if position > high or position < low:
                        speed = await self.speed()
                        if (position > high and speed > 0) or (position < low and speed < 0):
                            await core.stop()
                            log.warning("axis %s passed its soft limit at %g %s: stopped",
                                        self.name, position, self.unit)
                except Exception as exc:  # offline or a failed read: try again next period
                    self.last_error = exc
            await asyncio.sleep(period)

    async def stop(self) -> None:
        """Stop whatever runs (a lease of any owner, a tuning run: Stop always wins)."""
        await self._end_lease("stopped")
        tuning = self._tuning
        if tuning is not None and tuning[1] is not None and tuning[1] is not asyncio.current_task():
            tuning[1].cancel()  # its abort path stops the motor again and reverts the gains
        with self._commanding(moves=False), self._watch():
            await self.core().stop()
            self._moving = None

    async def _end_lease(self, why: str) -> None:
        lease, self._lease = self._lease, None
        if lease is not None and lease.task is not None and not lease.task.done():
            lease.ended = why
            lease.task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await lease.task

    async def enable(self) -> None:
        with self._watch():
            await self.core().enable()

    async def disable(self) -> None:
        with self._watch():
            await self.core().disable()

    async def reset(self) -> None:
        """The family's own reset; a DYN5's clears its power-cleared cell too (4.4), so the
        machine's token is left there again."""
        with self._watch():
            await self.core().reset()
        with contextlib.suppress(NotSupported, ArgumentRangeError):
            await self.mark_power()

    async def home(self) -> None:
        """The drive's own homing (AsyncAxis.home: NotSupported, saying why, where the
        family has none); returns once it is started, :meth:`wait_idle` waits for its end.
        A motion: refused while a power loss is unacknowledged."""
        core = self._motion()
        with self._commanding(), self._watch():
            await core.home()

    async def apply_profile(self) -> dict[str, int]:
        """The file's ``speed`` and ``accel`` as the drive's point-to-point profile
        (AsyncAxis.set_move_profile: read, written only where the drive differs), once per
        opened link: the parameters written ({} when the drive had them, or the file names
        neither). The CLI's ``move`` calls it before moving (docs/machine.md)."""
        core = self.core()
        if self._profile_for is core:
            return {}
        spec = self.spec
        rpm = None if spec.speed is None else abs(self.scale.to_rpm(spec.speed))
        accel = None if spec.accel is None else abs(self.scale.to_rpm(spec.accel))
        written: dict[str, int] = {}
        if rpm is not None or accel is not None:
            with self._watch():
                written = await core.set_move_profile(rpm, accel)
        if written:
            log.warning("axis %s: the drive's move profile set from the machine file: %s",
                        self.name, ", ".join(f"{k} = {v}" for k, v in written.items()))
        self._profile_for = core
        return written

    async def set_origin(self) -> None:
        """The position here becomes 0 counts (limits count from it)."""
        with self._watch():
            await self.core().set_origin()
        self._origin_pending = False

    async def wait_idle(self, timeout: float | None = None) -> AxisStatus:
        core = self.core()
        since = self._epoch
        with self._watch():
            status = await (core.wait_idle() if timeout is None else core.wait_idle(timeout))
        self._seen(status=status, since=since)
        return status

    async def apply_origin(self) -> None:
        """The file's origin rule at start-up: "set" sets the origin here, "home" runs the
        family's homing where the Axis has one (NotSupported otherwise)."""
        if self.spec.origin == "set":
            await self.set_origin()
        elif self.spec.origin == "home":
            try:
                await self.home()
                await self.wait_idle()  # the machine opens once the axis is homed
            except NotSupported as exc:
                raise NotSupported(f"{self.source}: axis {self.name}: origin: {exc}; use "
                                   "origin = \"set\"", family=exc.family) from None

    def skip_origin(self) -> None:
        """The link opened after start-up: the file's origin rule is not applied (one
        line); ``origin_pending`` tells until :meth:`set_origin`."""
        if self.spec.origin != "none":
            self._origin_pending = True
            log.warning("axis %s: origin = %r not applied (the link opened after start-up); "
                        "set it with set_origin()", self.name, self.spec.origin)

    async def _closed(self) -> None:
        """The machine closes: the lease ends (the machine stops the axes first)."""
        await self._end_lease("closed")
        self._is_closed = True

    def __repr__(self) -> str:
        state = "" if self.online else " offline"
        return f"<AsyncMachineAxis {self.name} {self.url} id {self.drive_id}{state}>"
