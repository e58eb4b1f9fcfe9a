"""``AsyncAxis.virtual_io()`` on ``sim://``: the virtual drives' JP3 I/O via DriveControl.

The Axis side (servobus.axis.virtual_io) knows no simulator; :mod:`servobus.sim.schemes`
gives every ``sim://`` axis of a DMM family a :class:`SimIoSource` over the drives it talks
to. Each call is one control-channel request (servobus.sim.dmm.control, docs/sim-control.md):
the same argument checks and ranges, from the same table. The in-process drives run in
wall-clock time on their line's clock, so no extra sync is needed before a request.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from servobus.errors import ArgumentRangeError
from servobus.sim.core.control import ControlError
from servobus.sim.dmm.control import COMMANDS, DriveControl
from servobus.sim.dmm.drive import VirtualDrive

#: Families whose virtual drives have the JP3 connector: the DMM drives (DYN2 manual 2.3,
#: 4.1-4.6; the DYN5 keeps the base pulse/analog capability, DYN5 spec 1). YZ-AIM motors
#: have no analog or pulse input: their axes get no virtual I/O.
JP3_FAMILY_PREFIX = "dmm-"


def has_jp3(family_name: str) -> bool:
    return family_name.startswith(JP3_FAMILY_PREFIX)


def _range(cmd: str, arg: str) -> list[float | None]:
    spec = next(a for a in COMMANDS[cmd].args if a.name == arg)
    return [spec.lo, spec.hi]


def _limits() -> dict[str, Any]:
    fmt = next(a for a in COMMANDS["pulses"].args if a.name == "format")
    return {"analog_v": _range("analog", "volts"), "pulse_rate_hz": _range("pulses", "rate"),
            "pulse_count": _range("pulses", "count"), "pulse_formats": list(fmt.choices)}


class SimIo:
    """One virtual drive's I/O (servobus.axis.virtual_io.VirtualIo)."""

    def __init__(self, control: DriveControl, drive_id: int) -> None:
        self._control = control
        self._id = drive_id

    def _call(self, cmd: str, **args: Any) -> dict[str, Any]:
        try:
            reply = self._control.call(cmd, self._id, **args)
        except ControlError as exc:  # bad_argument / unknown_id: the caller's values
            raise ArgumentRangeError(f"{cmd}: {exc}") from None
        return {k: v for k, v in reply.items() if k not in ("ok", "cmd")}

    def limits(self) -> dict[str, Any]:
        return _limits()

    async def set_analog(self, volts: float) -> dict[str, Any]:
        return self._call("analog", volts=volts)

    async def pulses(self, fmt: str | None, count: int,
                     rate: float | None = None) -> dict[str, Any]:
        args: dict[str, Any] = {"count": count}
        if fmt is not None:
            args["format"] = fmt
        if rate is not None:
            args["rate"] = rate
        return self._call("pulses", **args)

    async def set_enable(self, enabled: bool) -> dict[str, Any]:
        return self._call("ena", enabled=enabled)

    async def outputs(self) -> dict[str, Any]:
        return self._call("outputs")

    async def state(self) -> dict[str, Any]:
        return self._call("state")


class SimIoSource:
    """The VirtualIoSource of an in-process virtual line or bus."""

    def __init__(self, drives: Sequence[VirtualDrive]) -> None:
        self._control = DriveControl(drives)

    def for_drive(self, drive_id: int) -> SimIo:
        drives = self._control.drives
        if any(d.drive_id == drive_id for d in drives):
            return SimIo(self._control, drive_id)
        if len(drives) == 1:  # a front end that keeps its own id
            return SimIo(self._control, drives[0].drive_id)
        raise ArgumentRangeError(f"no virtual drive {drive_id} on this line")
