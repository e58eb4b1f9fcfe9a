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
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from typing import TYPE_CHECKING

from servobus.errors import (
    ArgumentRangeError,
    LimitError,
    MachineLinkError,
    NotSupported,
    OwnerError,
)
from servobus.machine.config import AxisSpec
from servobus.machine.lease import DEFAULT_TTL_S, Lease, check_speed, check_ttl, stream
from servobus.machine.units import Scale

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis
    from servobus.families.base import AxisStatus, Family

log = logging.getLogger(__name__)

UNITS_PER_S = {"mm": "mm/s", "deg": "deg/s", "rev": "rev/s", "counts": "counts/s"}


class AsyncMachineAxis:
    """One axis of a machine file; see the module docstring for the rules."""

    def __init__(self, spec: AxisSpec, source: str = "") -> None:
        self.spec = spec
        self.source = source  # the file, for messages
        self.axis: AsyncAxis | None = None  # the underlying Axis; None while offline
        self.last_error: BaseException | None = None
        self._lease: Lease | None = None

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
        if self.axis is None:
            why = f": {self.last_error}" if self.last_error is not None else ""
            raise MachineLinkError(f"axis {self.name} is offline ({self.url}){why}")
        return self.axis

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
        return await self.core().position()

    async def position(self) -> float:
        return self.to_user(await self.core().position())

    async def speed(self) -> float:
        """User units per second (the Axis reads motor rpm)."""
        return self.scale.from_rpm(await self.core().speed())

    async def status(self) -> AxisStatus:
        return await self.core().status()

    async def readings(self) -> tuple[float, float, AxisStatus]:
        """Position and speed in user units and the status (see ``AsyncAxis.readings``)."""
        position, speed, status = await self.core().readings()
        return self.to_user(position), self.scale.from_rpm(speed), status

    # ------------------------------------------------------------- motion
    async def move_to(self, target: float, *, wait: bool = False,
                      timeout: float | None = None) -> None:
        """Absolute move to ``target`` user units (checked against the limits first)."""
        self.check_target(target)
        counts = self.to_counts(target)
        await self._end_lease("replaced by a move")
        await self.core().move_to(counts, wait=wait, timeout=timeout)

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
        await self.core().move_by(counts, wait=wait, timeout=timeout)

    async def turn(self, speed: float | None = None, *, owner: str = "api",
                   ttl: float = DEFAULT_TTL_S) -> None:
        """Constant speed in user units per second (None: the file's ``speed``; 0 stops).

        On a ``continuous`` axis an open-ended speed command. On any other axis a lease
        (:meth:`jog`): it ends ``ttl`` seconds after the last call unless called again."""
        if self.spec.continuous or self.core().continuous:
            speed = self._checked_speed(speed)
            rpm = round(self.scale.to_rpm(speed))
            await self._end_lease("replaced by an open-ended speed")
            await self.core().turn(rpm)
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
        lease = self._lease if self._lease is not None and self._lease.alive else None
        if lease is not None and lease.owner != owner:
            raise OwnerError(f"axis {self.name} is held by {lease.owner}; stop it first "
                             "(Stop and STOP ALL always win)", owner=lease.owner)
        if speed == 0:
            if lease is not None:
                await self.stop()
            return
        heading = 1 if speed > 0 else -1
        if lease is not None and lease.heading == heading:
            lease.speed = speed  # the streamer picks the new speed up at its next update
            lease.renew(ttl)
            return
        core = self.core()
        rpm = self.scale.to_rpm(speed)
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
        new = Lease(owner, speed, accel, limit, time.monotonic() + ttl)
        new.task = asyncio.create_task(self._stream(new), name=f"lease {self.name}")
        self._lease = new

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
        rpm = abs(self.scale.to_rpm(lease.speed))

        async def read() -> float:
            return self.to_user(await core.position())

        async def send(target: float) -> None:
            await core.stream_to(self.to_counts(target), abs(self.scale.to_rpm(lease.speed))
                                 or rpm)

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

    def _beyond(self, position: float, heading: int) -> bool:
        assert self.limits is not None
        low, high = self.limits
        return position >= high if heading > 0 else position <= low

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
                    position = self.to_user(await core.position())
                    if position > high or position < low:
                        speed = self.scale.from_rpm(await core.speed())
                        if (position > high and speed > 0) or (position < low and speed < 0):
                            await core.stop()
                            log.warning("axis %s passed its soft limit at %g %s: stopped",
                                        self.name, position, self.unit)
                except Exception as exc:  # offline or a failed read: try again next period
                    self.last_error = exc
            await asyncio.sleep(period)

    async def stop(self) -> None:
        """Stop whatever runs (a lease of any owner too: Stop always wins)."""
        await self._end_lease("stopped")
        await self.core().stop()

    async def _end_lease(self, why: str) -> None:
        lease, self._lease = self._lease, None
        if lease is not None and lease.task is not None and not lease.task.done():
            lease.ended = why
            lease.task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await lease.task

    async def enable(self) -> None:
        await self.core().enable()

    async def disable(self) -> None:
        await self.core().disable()

    async def reset(self) -> None:
        await self.core().reset()

    async def set_origin(self) -> None:
        """The position here becomes 0 counts (limits count from it)."""
        await self.core().set_origin()

    async def wait_idle(self, timeout: float | None = None) -> AxisStatus:
        core = self.core()
        return await (core.wait_idle() if timeout is None else core.wait_idle(timeout))

    async def apply_origin(self) -> None:
        """The file's origin rule at start-up: "set" sets the origin here, "home" runs the
        family's homing where the Axis has one (NotSupported otherwise)."""
        if self.spec.origin == "set":
            await self.set_origin()
        elif self.spec.origin == "home":
            home = getattr(self.core(), "home", None)
            if home is None:
                core = self.core()
                raise NotSupported(f"{self.source}: axis {self.name}: origin: "
                                   f"{core.family.title} over {core.protocol} has no "
                                   "homing; use origin = \"set\"", family=core.family.name)
            await home()

    async def _closed(self) -> None:
        """The machine closes: the lease ends (the machine stops the axes first)."""
        await self._end_lease("closed")

    def __repr__(self) -> str:
        state = "" if self.online else " offline"
        return f"<AsyncMachineAxis {self.name} {self.url} id {self.drive_id}{state}>"
