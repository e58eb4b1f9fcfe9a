"""Commands from OPC UA methods and MQTT messages: one check, one call, one log line.

Both front ends hand a command here; the answer is a :class:`Refused` carrying the OPC UA
status code name that says what was wrong (MQTT replies carry the same name).

Decisions (docs/gateway.md "Commands"):

* every command needs an authenticated user, Stop and StopAll included: anonymous
  clients are read-only (an unknown program that can stop a production line is a fault
  too); a person at the machine has its own stop;
* values are in the axis's unit, finite; MoveAbsolute is checked against the axis limits
  here, MoveRelative by the machine (it knows the position), both as BadOutOfRange;
* an offline axis answers BadCommunicationError at once; a command never waits longer than
  :data:`COMMAND_DEADLINE_S` and is never re-sent;
* ``ack`` (OPC UA ``Acknowledge``) is the machine axis's ``acknowledge()``: a person or
  program has seen a possible power loss and an interrupted motion (docs/machine.md
  "Recovery"), and motion is allowed again. Nothing is sent to the drive, but it re-arms
  motion, so it needs a user as the motion methods do (MQTT: an ``id`` and ``ts`` too, so a
  replayed or late ack never acknowledges a power loss its sender did not see). Refused
  while the axis is offline and while its reopened link is checked for a power loss
  (BadCommunicationError, "try again"): an acknowledgement only covers what can be seen;
* a motion refused because of an unacknowledged power loss (PowerLostError) is
  BadInvalidState, as a drive in alarm;
* ``set_speed`` is a lease of the axis (servobus.machine.lease, docs/safety.md) held by the
  command's *owner* (an OPC UA session, an MQTT client) for ``ttl`` seconds (above 0, at
  most 1: BadOutOfRange beyond) after each call; calling again renews it. Another owner's
  live lease answers BadLocked naming the holder. On a ``continuous`` axis the speed is
  open-ended and the ttl is only checked. :meth:`Commander.release` lets an owner's leases
  go (a closed session).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    NotSupported,
    OwnerError,
    PowerLostError,
    ServobusError,
)
from servobus.gateway.refusals import RefusalLog
from servobus.gateway.source import Machine, MachineAxis
from servobus.machine.lease import DEFAULT_TTL_S
from servobus.machine.lease import check_ttl as lease_ttl

log = logging.getLogger(__name__)

COMMAND_DEADLINE_S = 5.0

#: Command name -> takes a value. The OPC UA method names are the CamelCase of these.
AXIS_COMMANDS: dict[str, bool] = {
    "move_absolute": True, "move_relative": True, "set_speed": True, "stop": False,
    "enable": False, "disable": False, "reset_alarm": False, "ack": False,
}
#: Commands that start a motion or allow it again (MQTT requires an id and a timestamp).
MOTION = frozenset({"move_absolute", "move_relative", "set_speed", "enable", "reset_alarm",
                    "ack"})


class Refused(Exception):
    """A command not carried out; ``code`` is the OPC UA status code name."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


def status_name(exc: BaseException) -> str:
    """The OPC UA status code name for a failure of a drive call."""
    if isinstance(exc, ArgumentRangeError):  # LimitError included
        return "BadOutOfRange"
    if isinstance(exc, DriveAlarm | PowerLostError):
        return "BadInvalidState"
    if isinstance(exc, DriveTimeout | TimeoutError):
        return "BadTimeout"
    if isinstance(exc, ConnectionLost | ConnectionError | OSError):
        return "BadCommunicationError"
    if isinstance(exc, NotSupported):
        return "BadNotSupported"
    if isinstance(exc, OwnerError):  # "locked by a different application" (Part 4)
        return "BadLocked"
    if isinstance(exc, DriveError | ServobusError):
        return "BadDeviceFailure"
    return "BadInternalError"


@dataclass(frozen=True)
class Command:
    axis: str  # "" for stop_all
    name: str
    value: float | None = None
    ttl: float | None = None  # set_speed only: the lease's time to live (None: DEFAULT_TTL_S)


class Commander:
    def __init__(self, machine: Machine) -> None:
        self.machine = machine
        self.refusals = RefusalLog()

    def check(self, user: str | None, command: Command) -> MachineAxis | None:
        """Refused unless ``user`` may run ``command`` with these arguments."""
        if not user:
            raise Refused("BadUserAccessDenied",
                          "an authenticated user is required to command the machine")
        if command.name == "stop_all":
            return None
        takes_value = AXIS_COMMANDS.get(command.name)
        if takes_value is None:
            raise Refused("BadMethodInvalid", f"unknown command {command.name!r}")
        axis = self.machine.axes.get(command.axis)
        if axis is None:
            raise Refused("BadNodeIdUnknown", f"no axis {command.axis!r} on this machine")
        if takes_value:
            value = command.value
            if (isinstance(value, bool) or not isinstance(value, int | float)
                    or not math.isfinite(value)):
                raise Refused("BadInvalidArgument",
                              f"{command.name} needs a finite number in {axis.unit}")
            if command.name == "move_absolute" and axis.limits is not None:
                low, high = axis.limits
                if not low <= value <= high:
                    raise Refused("BadOutOfRange",
                                  f"target {value:g} {axis.unit} is outside the limits "
                                  f"{low:g}..{high:g} {axis.unit} of axis {axis.name}")
        check_ttl(command)
        if not axis.online:
            raise Refused("BadCommunicationError", f"axis {axis.name} is offline")
        if command.name == "ack" and axis.checking:
            raise Refused("BadCommunicationError",
                          f"axis {axis.name}: its link is back and being checked for a power "
                          "loss; nothing was acknowledged, try again")
        return axis

    async def run(self, user: str | None, command: Command, via: str,
                  owner: str | None = None) -> None:
        """Check and carry out ``command``; Refused on any failure (logged in one line).
        ``owner`` holds a ``set_speed`` lease (default ``via:user``)."""
        what = command.name + ("" if command.value is None else f" {command.value:g}") \
            + ("" if command.ttl is None else f" ttl {command.ttl:g} s")
        target = command.axis or self.machine.name
        try:
            axis = self.check(user, command)
            async with asyncio.timeout(COMMAND_DEADLINE_S):
                await self._call(axis, command, owner or f"{via}:{user}")
        except Refused as exc:
            suffix = self.refusals.admit(f"{via} {user or 'anonymous'}")
            if suffix is not None:  # one line per spell (servobus.gateway.refusals)
                log.warning("%s %s: %s %s refused (%s): %s%s", via, user or "anonymous",
                            target, what, exc.code, exc.message, suffix)
            raise
        except Exception as exc:
            code = status_name(exc)
            log.warning("%s %s: %s %s failed (%s): %s", via, user, target, what, code, exc)
            raise Refused(code, f"{type(exc).__name__}: {exc}") from None
        log.info("%s %s: %s %s", via, user, target, what)

    async def release(self, owner: str, via: str) -> None:
        """``owner`` is gone (a closed session): its leases end and their axes stop.
        Never raises: one log line per axis it held, or per failure."""
        for axis in self.machine.axes.values():
            lease = axis.lease
            if lease is None or lease.owner != owner:
                continue
            try:
                async with asyncio.timeout(COMMAND_DEADLINE_S):
                    await axis.release(owner)
            except Exception as exc:
                log.warning("%s: %s left; stopping axis %s failed: %s", via, owner, axis.name,
                            exc)
            else:
                log.info("%s: %s left; its motion of axis %s stopped", via, owner, axis.name)

    async def _call(self, axis: MachineAxis | None, command: Command, owner: str) -> None:
        if axis is None:
            await self.machine.stop_all()
            return
        calls: dict[str, Callable[[], Awaitable[None]]] = {
            "stop": axis.stop, "enable": axis.enable, "disable": axis.disable,
            "reset_alarm": axis.reset, "ack": axis.acknowledge,
        }
        if command.name in calls:
            await calls[command.name]()
            return
        value = float(command.value or 0.0)
        if command.name == "move_absolute":
            await axis.move_to(value)
        elif command.name == "move_relative":
            await axis.move_by(value)
        else:
            ttl = DEFAULT_TTL_S if command.ttl is None else command.ttl
            await axis.turn(value, owner=owner, ttl=ttl)


def check_ttl(command: Command) -> None:
    """A ttl only on set_speed, a finite number of seconds in (0, MAX_TTL_S]."""
    ttl = command.ttl
    if ttl is None:
        return
    if command.name != "set_speed":
        raise Refused("BadInvalidArgument", f"{command.name} takes no ttl (set_speed does)")
    if isinstance(ttl, bool) or not isinstance(ttl, int | float) or not math.isfinite(ttl):
        raise Refused("BadInvalidArgument", "ttl is a finite number of seconds")
    try:
        lease_ttl(ttl)  # the lease's own range, (0, MAX_TTL_S]
    except ArgumentRangeError as exc:
        raise Refused("BadOutOfRange", f"{exc}; call again to renew it") from None
