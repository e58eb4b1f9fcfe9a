"""One drive (``--url``) or one machine axis (``--machine``/``--axis``) for the commands that
act on either the same way: ``enable``, ``disable``, ``origin``, ``home``, ``jog``.

A single drive is opened as the Axis (``enable``, ``origin`` ...) or as a one-axis machine
when the command holds a motion (``jog``: a lease, docs/safety.md); a machine axis is its
MachineAxis. Positions read in the drive's counts on a drive, in the axis's unit on a
machine axis.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from servobus.cli import machine_cli
from servobus.cli.context import CliContext
from servobus.cli.open_axis import open_axis
from servobus.cli.output import fixed
from servobus.errors import DriveTimeout

if TYPE_CHECKING:
    from servobus.axis.types import AxisStatus

#: Seconds between status reads while a command waits for the drive to show a change.
POLL_S = 0.05


class OneAxis(Protocol):
    """What these commands call: the sync Axis and the MachineAxis both have it."""

    def enable(self) -> None: ...
    def disable(self) -> None: ...
    def set_origin(self) -> None: ...
    def home(self) -> None: ...
    def stop(self) -> None: ...
    def status(self) -> AxisStatus: ...
    def position(self) -> float: ...
    def wait_idle(self, timeout: float) -> AxisStatus: ...


@dataclass(frozen=True)
class Opened:
    """The axis a command acts on, how to name it, and how to read where it is."""

    axis: OneAxis
    who: str  # "drive 1" or "axis x"
    key: dict[str, object]  # {"drive_id": 1} or {"axis": "x"}: the --json identity
    unit: str  # "counts", or the machine axis's unit

    def position(self) -> float:
        """Counts on a drive, the axis's unit on a machine axis."""
        return float(self.axis.position())

    def where(self) -> str:
        value = self.position()
        shown = f"{int(value)}" if self.unit == "counts" else fixed(value, 4)
        return f"{shown} {self.unit}"


@contextmanager
def open_one(ctx: CliContext) -> Iterator[Opened]:
    """The drive or machine axis the global options name (closed without a stop)."""
    if ctx.machine_mode:
        with machine_cli.open_machine_axis(ctx) as axis:
            yield Opened(axis, f"axis {axis.name}", {"axis": axis.name}, axis.unit)
        return
    with open_axis(ctx) as drive:
        yield Opened(drive, f"drive {drive.drive_id}", {"drive_id": drive.drive_id}, "counts")


def status_when(axis: OneAxis, timeout: float, enabled: bool | None = None) -> AxisStatus:
    """Status reads until ``enabled`` matches (None: the first status), or ``timeout``
    seconds pass; the last status read. A read that times out is tried again until then
    (a drive restarting after a reset does not answer for a while)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            status = axis.status()
        except DriveTimeout:
            if time.monotonic() >= deadline:
                raise
        else:
            if enabled is None or status.enabled == enabled or time.monotonic() >= deadline:
                return status
        time.sleep(POLL_S)
