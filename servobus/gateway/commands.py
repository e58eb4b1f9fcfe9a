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
  :data:`COMMAND_DEADLINE_S` and is never re-sent.
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
    ServobusError,
)
from servobus.gateway.source import Machine, MachineAxis

log = logging.getLogger(__name__)

COMMAND_DEADLINE_S = 5.0

#: Command name -> takes a value. The OPC UA method names are the CamelCase of these.
AXIS_COMMANDS: dict[str, bool] = {
    "move_absolute": True, "move_relative": True, "set_speed": True, "stop": False,
    "enable": False, "disable": False, "reset_alarm": False,
}
#: Commands that start a motion (MQTT requires an id and a timestamp on these).
MOTION = frozenset({"move_absolute", "move_relative", "set_speed", "enable", "reset_alarm"})


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
    if isinstance(exc, DriveAlarm):
        return "BadInvalidState"
    if isinstance(exc, DriveTimeout | TimeoutError):
        return "BadTimeout"
    if isinstance(exc, ConnectionLost | ConnectionError | OSError):
        return "BadCommunicationError"
    if isinstance(exc, NotSupported):
        return "BadNotSupported"
    if isinstance(exc, DriveError | ServobusError):
        return "BadDeviceFailure"
    return "BadInternalError"


@dataclass(frozen=True)
class Command:
    axis: str  # "" for stop_all
    name: str
    value: float | None = None


class Commander:
    def __init__(self, machine: Machine) -> None:
        self.machine = machine

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
        if not axis.online:
            raise Refused("BadCommunicationError", f"axis {axis.name} is offline")
        return axis

    async def run(self, user: str | None, command: Command, via: str) -> None:
        """Check and carry out ``command``; Refused on any failure (logged in one line)."""
        what = command.name + ("" if command.value is None else f" {command.value:g}")
        target = command.axis or self.machine.name
        try:
            axis = self.check(user, command)
            async with asyncio.timeout(COMMAND_DEADLINE_S):
                await self._call(axis, command)
        except Refused as exc:
            log.warning("%s %s: %s %s refused (%s): %s", via, user or "anonymous", target, what,
                        exc.code, exc.message)
            raise
        except Exception as exc:
            code = status_name(exc)
            log.warning("%s %s: %s %s failed (%s): %s", via, user, target, what, code, exc)
            raise Refused(code, f"{type(exc).__name__}: {exc}") from None
        log.info("%s %s: %s %s", via, user, target, what)

    async def _call(self, axis: MachineAxis | None, command: Command) -> None:
        if axis is None:
            await self.machine.stop_all()
            return
        calls: dict[str, Callable[[], Awaitable[None]]] = {
            "stop": axis.stop, "enable": axis.enable, "disable": axis.disable,
            "reset_alarm": axis.reset,
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
            await axis.turn(value)
