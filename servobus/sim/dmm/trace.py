"""The DMM drive as its 4 kHz trace sees it (:mod:`servobus.sim.core.capture`): its own id,
its own counts, its status bits as the Axis has them."""

from __future__ import annotations

from typing import Protocol

from servobus.axis.capture import status_bits
from servobus.axis.types import motion_state
from servobus.families.dmm import units as U
from servobus.sim.core.capture import Clocked, Readouts


class TracedDrive(Clocked, Readouts, Protocol):
    """What the trace reads of a DMM VirtualDrive (typed here: the drive imports this)."""

    @property
    def drive_id(self) -> int: ...
    @property
    def position(self) -> int: ...
    def trace_flags(self) -> tuple[bool, bool, bool, bool]:
        """enabled, motion busy, on position, alarm."""
        ...


class DriveTrace:
    """A DMM VirtualDrive as the host sees it: its own id and counts."""

    __slots__ = ("drive",)
    counts_per_rev = U.COUNTS_PER_REV

    def __init__(self, drive: TracedDrive) -> None:
        self.drive = drive

    @property
    def trace_id(self) -> int:
        return self.drive.drive_id

    def trace_sample(self) -> tuple[float, float, float, float, int]:
        d = self.drive
        speed = d.speed_rpm
        enabled, busy, on_position, alarm = d.trace_flags()
        moving, in_position = motion_state(busy, on_position, speed)  # as AxisStatus has them
        return (d.position, d.position_error, speed, d.current_a,
                status_bits(enabled, moving, in_position, alarm))
