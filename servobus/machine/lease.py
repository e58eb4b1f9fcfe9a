"""Leases: open-ended motion that ends by itself unless its owner keeps it alive (issue 27).

A jog or a constant speed on an axis that is not ``continuous`` is never a speed command the
drive would keep for ever. It is a stream of position targets, each a bounded distance (the
*lead*) ahead of the motor, sent with the drive's own target update
(:meth:`servobus.axis.base.AsyncAxis.stream_to`: DMM DTPU over DYN232M and DYN CAN, DYN5
Go_Absolute_Pos over explicit messaging, YZ-AIM's absolute position at a cruise speed):

* every :data:`STREAM_S` the streamer reads the position ``p`` and moves the target on by
  the asked speed times the time since the last update, but never more than ``lead`` ahead
  of ``p`` and never past the soft limit it heads for. The target advances at the asked
  speed, so the motor cruises at it;
* ``lead = v^2 / (2 a) + v x STREAM_S``: the stopping distance from the asked speed ``v`` at
  the drive's own acceleration ``a`` (:class:`StreamProfile`) plus one update's travel;
* the owner renews the lease (:meth:`Lease.renew`) before its ``ttl`` runs out. When it
  does not, the streamer stops sending and commands a stop; when the whole host dies, the
  drive simply reaches the last target and rests there: at most ``lead`` past the position
  of the last update, and never past the limit;
* a link that fails ends the lease (one log line); a lease is never resumed: a new motion
  needs a new call from its owner.

docs/safety.md gives the bound per family and the measured figures.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from servobus.axis.types import StreamProfile
from servobus.errors import ArgumentRangeError, DriveTimeout

log = logging.getLogger(__name__)

#: Period of target updates while a lease runs, seconds.
STREAM_S = 0.05
#: A lease's time to live when the caller names none, and the most it may be, seconds
#: (the owner's death must stop the motor within a second).
DEFAULT_TTL_S = 0.5
MAX_TTL_S = 1.0


def check_ttl(ttl: object) -> float:
    """A finite ttl in (0, MAX_TTL_S] seconds, else ArgumentRangeError."""
    if isinstance(ttl, bool) or not isinstance(ttl, int | float) or not math.isfinite(ttl) \
            or not 0 < ttl <= MAX_TTL_S:
        raise ArgumentRangeError(f"ttl must be a number of seconds above 0 and at most "
                                 f"{MAX_TTL_S:g}, got {ttl!r}")
    return float(ttl)


def lead(speed: float, accel: float, period: float = STREAM_S) -> float:
    """How far ahead of the motor a target may run: stopping distance plus one period."""
    v = abs(speed)
    return v * v / (2.0 * accel) + v * period


@dataclass
class Lease:
    """One open-ended motion of one axis, in the axis's user units."""

    owner: str
    speed: float  # user units per second, signed
    accel: float  # the drive's acceleration, user units per second squared
    limit: float | None  # the soft limit it heads for, None without one
    until: float  # time.monotonic() at which it ends unless renewed
    at_limit: bool = False  # the target stands at the limit (the motion went as far as allowed)
    ended: str = ""  # why it ended ("" while it runs)
    #: The drive's profile the lease started on (a renewal's new speed is checked on it).
    profile: StreamProfile | None = None
    task: asyncio.Task[None] | None = field(default=None, repr=False)

    @property
    def heading(self) -> int:
        return 1 if self.speed > 0 else -1

    @property
    def lead(self) -> float:
        return lead(self.speed, self.accel)

    @property
    def alive(self) -> bool:
        return self.task is not None and not self.task.done()

    def renew(self, ttl: float) -> None:
        self.until = time.monotonic() + ttl

    def next_target(self, target: float | None, position: float, elapsed: float) -> float:
        """Where the next update puts the target (module docstring)."""
        h = self.heading
        ahead = self.lead if target is None else min(h * (target - position)
                                                     + abs(self.speed) * elapsed, self.lead)
        new = position + h * max(ahead, 0.0)
        if target is not None and h * (new - target) < 0:
            # Decision: a target never steps back. A position read that lags the motor (a
            # late reply, a slow host) would otherwise put the target behind it and reverse
            # the axis; the last target was at most one lead ahead of a motor that never
            # passes it, so holding it keeps the bound.
            new = target
        if self.limit is not None and h * (new - self.limit) >= 0:
            self.at_limit = True
            return self.limit
        self.at_limit = False
        return new


Reader = Callable[[], Awaitable[float]]
Sender = Callable[[float], Awaitable[None]]
Stopper = Callable[[], Awaitable[None]]


async def stream(lease: Lease, name: str, read: Reader, send: Sender, stop: Stopper) -> None:
    """Run ``lease`` until it expires (then ``stop``), fails (then ``stop``, once, logged)
    or is cancelled (the canceller stops the axis).

    Decision: a reply that misses its deadline (DriveTimeout, after the link's own bounded
    retries of a read) is not a dropped link. Without a fresh position no update is sent
    (the drive rests at the last target by itself), and the lease goes on; it ends when no
    read has succeeded for :data:`MAX_TTL_S`, or at once when the link is lost."""
    target: float | None = None
    heading = lease.heading
    last = time.monotonic()
    good = last  # the last successful read
    position: float | None = None
    try:
        while True:
            if position is None:
                position = await _fresh(read)
                now = time.monotonic()
                if position is None:
                    if now - good >= MAX_TTL_S:
                        raise DriveTimeout(f"no position read for {MAX_TTL_S:g} s")
                    if now >= lease.until:
                        lease.ended = "expired"
                        break
                    await asyncio.sleep(STREAM_S)
                    continue
                good = now
            now = time.monotonic()
            if now >= lease.until:
                lease.ended = "expired"
                break
            if lease.heading != heading:  # reversed: start again from the motor
                target, heading = None, lease.heading
            target = lease.next_target(target, position, now - last)
            last = now
            with contextlib.suppress(DriveTimeout):  # sent once, never again; next one new
                await send(target)
            await asyncio.sleep(STREAM_S)
            position = await _fresh(read)
    except asyncio.CancelledError:
        lease.ended = lease.ended or "stopped"
        raise
    except Exception as exc:  # the link failed: the lease ends, never resumed
        if lease.ended:  # the machine ended it (its link dropped) and said so
            log.debug("axis %s: its %s motion ended (%s)", name, lease.owner, lease.ended)
        else:
            lease.ended = f"failed: {exc}"
            log.warning("axis %s: its %s motion ended (%s); stopping it", name, lease.owner,
                        exc)
    else:
        log.info("axis %s: the motion of %s was not renewed within its ttl: stopping",
                 name, lease.owner)
    with contextlib.suppress(Exception):
        await stop()


async def _fresh(read: Reader) -> float | None:
    """The position, or None when the reply missed its deadline."""
    try:
        return await read()
    except DriveTimeout:
        return None


def check_speed(name: str, speed: float, rpm: float, profile: StreamProfile,
                unit: str, to_user: Callable[[float], float]) -> None:
    """Refuse a speed above what the drive's own profile runs, naming the limit in
    ``unit`` (the drive's EEPROM parameters are never raised per motion)."""
    if abs(rpm) > profile.max_rpm:
        raise ArgumentRangeError(
            f"axis {name}: {abs(speed):g} {unit} is above what the drive's max_speed allows "
            f"({abs(to_user(profile.max_rpm)):g} {unit}); nothing was sent")
