"""A move that did not end where it was asked says so (``move --wait`` / ``--confirm``;
issue 28), on one drive and on a machine axis alike.

Decisions:

* Before the send, ``--wait`` and ``--confirm`` read the status once: a drive in alarm
  (DriveAlarm) or disabled (MoveFailed) would not move, so nothing is sent and the command
  exits 1 - a disabled drive used to "finish" a waited move at once, wherever it stood.
* After ``--wait``: the drive must still be enabled, and the position within the drive's
  in-position window of the target (DMM OnRange, YZ-AIM +-10 counts); otherwise MoveFailed
  (exit 1) naming where it stopped. A target in raw command units (``120cmd``) has no count
  to compare with: only the enable is checked.
* A drive that stands still off its target never reports "idle" on a family whose
  in-position flag compares with the target (YZ-AIM): :func:`wait_arrival` waits as
  ``wait_idle`` does, and ends early once the motor has stood still (not moving, its
  position unchanged within the in-position window) for :data:`STILL_S` without being in
  position (a stop from another program, a blocked axis), so the command
  fails at once with MoveFailed instead of waiting out ``--wait-timeout`` (DriveTimeout).
* The checks live here, in the CLI, not in ``Axis.move_to(wait=True)``: a script decides
  itself what a move that ended elsewhere means (``wait_idle`` returns the status).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from servobus.cli.failures import EXIT_USAGE, CliError
from servobus.errors import DriveAlarm, DriveTimeout, MoveFailed

if TYPE_CHECKING:
    from servobus.axis.sync import Axis
    from servobus.axis.types import AxisStatus

#: How long a motor must stand still, not in position, before a waited move counts as
#: stopped off its target (far longer than the instant between a send and the start).
STILL_S = 1.0
#: Each ``wait_idle`` of :func:`wait_arrival` lasts at most this long between the checks.
SLICE_S = 0.25


class StillMoving(CliError, DriveTimeout):
    """``--wait`` ran out of ``--wait-timeout`` while the drive answered and was still on
    its way: the cause is the time given, not the link (no --id, wiring or --baud advice).
    Still a DriveTimeout for whoever catches that."""

    def __init__(self, what: str) -> None:
        super().__init__(what, "give --wait-timeout more seconds; the drive was not stopped "
                               "(`servobus stop` stops it)", EXIT_USAGE)


def wait_arrival(axis: Axis, timeout: float, window: int) -> AxisStatus:
    """``axis.wait_idle(timeout)``, ended early by a disabled drive or by a motor that stands
    still off its target: not moving, and its position within ``window`` counts of where it
    was, on reads :data:`STILL_S` apart (module docstring). The status to judge with
    :func:`check_arrival`."""
    deadline = time.monotonic() + timeout
    still: tuple[float, int] | None = None  # since when, and where, the motor stands
    while True:
        remaining = deadline - time.monotonic()
        try:
            status: AxisStatus = axis.wait_idle(timeout=max(0.001, min(SLICE_S, remaining)))
            return status
        except DriveTimeout:
            status = axis.status()
            if remaining <= SLICE_S:
                raise StillMoving(
                    f"drive {axis.drive_id} still moving after {timeout:g} s "
                    f"(moving={status.moving}, in_position={status.in_position})") from None
        if not status.enabled:
            return status
        here, now = axis.position(), time.monotonic()
        if status.moving or still is None or abs(here - still[1]) > window:
            still = None if status.moving else (now, here)
        elif now - still[0] >= STILL_S:
            return status


def check_ready(who: str, drive_id: int, status: AxisStatus) -> None:
    """Refuse a move the drive would not make: latched alarm or disabled; nothing sent."""
    if status.alarm_latched:
        raise DriveAlarm(f"{who}: alarm {status.alarm_code}: {status.alarm_text} (latched); "
                         "the move was not sent", code=status.alarm_code, drive_id=drive_id)
    if not status.enabled:
        raise MoveFailed(f"{who} is disabled (motor free): the move was not sent",
                         drive_id=drive_id)


def check_arrival(who: str, drive_id: int, status: AxisStatus, position: int,
                  target: int | None, window: int, where: str = "") -> None:
    """MoveFailed when a waited move ended disabled or off its target beyond ``window``
    (counts); ``where`` adds the position in the user's unit to the message."""
    at = f"{position} counts{where}"
    if not status.enabled:
        raise MoveFailed(f"{who} was disabled during the move; stopped at {at}",
                         drive_id=drive_id, position=position, target=target)
    if target is not None and abs(position - target) > window:
        raise MoveFailed(f"{who} stopped at {at}, {position - target:+d} counts from the "
                         f"target {target}: outside its in-position window of +-{window} "
                         "counts (blocked, too weak, or stopped by another program?)",
                         drive_id=drive_id, position=position, target=target)


def read_status(axis: Axis) -> AxisStatus:
    """The status, also of a drive that pushed its alarm: such an alarm is raised once, by
    the next call (DriveAlarm without the code); the status read after it names the code."""
    try:
        status: AxisStatus = axis.status()
    except DriveAlarm:
        status = axis.status()
    return status
