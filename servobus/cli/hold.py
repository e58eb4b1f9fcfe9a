"""``speed`` held by the command: a lease the process renews while it runs (issue 27).

On an axis that is not ``continuous`` a constant speed is a lease (servobus.machine.lease):
position targets streamed a bounded lead ahead of the motor, ending by themselves ``TTL_S``
after the last renewal. The command is the owner: its main thread renews every
:data:`RENEW_S` until ``--for SECONDS`` pass, Ctrl-C/SIGTERM, or the target stands at a soft
limit with the motor at rest; then it stops the axis. When the process dies (``kill -9``,
a hung main thread, a closed terminal), renewals stop and the drive comes to rest within
the lead of the last one (docs/safety.md gives the bound per family).

Decisions:

* The renewal runs on the main thread, not beside it: a main thread that hangs stops
  renewing, so the motion ends with it.
* A renewal never restarts a motion that has ended (``MachineAxis.renew`` returns False):
  a link failure or an expiry ends the command with one line, exit 1.
* On a ``continuous`` axis the speed is open-ended and the command returns at once, as
  before leases; with ``--for`` it waits and stops (the host stops it, docs/safety.md).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.output import note

if TYPE_CHECKING:
    from servobus.machine import MachineAxis

#: How often the command renews its lease, and the lease's time to live, seconds: two
#: renewals may be late (a loaded machine) before the motion ends by itself.
RENEW_S = 0.2
TTL_S = 0.5


def owner() -> str:
    """The lease's owner as other front ends name it in an OwnerError."""
    return f"servobus speed (pid {os.getpid()})"


@dataclass(frozen=True)
class Held:
    """How a held speed ended: ``why`` is ``"for"`` (the time ran out), ``"limit"`` (the
    target stood at a soft limit and the motor came to rest there) or ``"continuous"``
    (open-ended: the command returned at once)."""

    why: str
    seconds: float


def hold_speed(axis: MachineAxis, speed: float, seconds: float | None,
               announce: str | None = None) -> Held:
    """Turn ``axis`` at ``speed`` (its unit per second) for as long as the command holds it;
    see the module docstring. ``announce``: a stderr line once the motion runs."""
    with stop_on_interrupt(axis):
        continuous = axis.continuous or (axis.axis is not None and axis.axis.continuous)
        if speed == 0:  # ramps down whatever runs (a lease of any owner too)
            axis.stop()
            return Held("stopped", 0.0)
        who = owner()
        axis.turn(speed, owner=who, ttl=TTL_S)
        t0 = time.monotonic()
        if continuous and seconds is None:
            return Held("continuous", 0.0)
        if announce:
            note(announce)
        why = _renew_until(axis, who, t0, seconds, continuous)
        axis.stop()
        return Held(why, time.monotonic() - t0)


def _renew_until(axis: MachineAxis, who: str, t0: float, seconds: float | None,
                 continuous: bool) -> str:
    lease = axis.lease
    while True:
        now = time.monotonic()
        if seconds is not None and now - t0 >= seconds:
            return "for"
        if not continuous:
            if lease is not None and lease.at_limit and _resting_at_limit(axis, lease.limit):
                return "limit"
            if not axis.renew(who, TTL_S):
                why = lease.ended if lease is not None and lease.ended else "ended"
                raise CliError(f"axis {axis.name}: the held speed ended ({why}); the drive "
                               "rests at its last target", "check the link and the drive, "
                               "then run the command again", EXIT_FAULT)
        left = RENEW_S if seconds is None else min(RENEW_S, t0 + seconds - now)
        time.sleep(max(left, 0.0))


def _resting_at_limit(axis: MachineAxis, limit: float | None) -> bool:
    """The motor came to rest at the limit its target stands at (the target reaches the
    limit a lead before the motor does: position and stillness both count)."""
    core = axis.axis
    if limit is None or core is None:
        return False
    near = abs(axis.to_user(max(core.counts_per_rev / 1024, core.position_window())))
    return abs(axis.position() - limit) <= near and not axis.status().moving


def speed_words(speed: str, held: Held) -> str:
    """What a ``speed`` command did, in one line."""
    if held.why == "continuous":
        return f"turning at {speed} (continuous: open-ended, `servobus stop` stops it)"
    if held.why == "stopped":
        return "stopping"
    return f"turned at {speed} for {held.seconds:.2f} s, then stopped"
