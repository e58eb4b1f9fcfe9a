"""The machine file's ``speed`` and ``accel`` for the CLI's ``move`` (issue 32).

Before ``move`` (and ``move --together``) sends anything, each machine axis it moves gets
the file's speed and acceleration as its drive's point-to-point profile
(MachineAxis.apply_profile -> AsyncAxis.set_move_profile): the drive's parameters are read
and written only where they differ, never per move (on DMM drives they are EEPROM
parameters). A write is announced on stderr in one line per axis, and listed under
``profile_written`` in ``--json``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.cli.output import note

if TYPE_CHECKING:
    from servobus.machine import MachineAxis


def apply_profile(axis: MachineAxis) -> dict[str, int]:
    """Apply the file's profile to ``axis``; one stderr line when a parameter was written."""
    written = axis.apply_profile()
    if written:
        values = ", ".join(f"{name} = {value}" for name, value in written.items())
        note(f"note: axis {axis.name}: the drive's move profile now follows the machine "
             f"file's speed/accel ({values}; written once, kept by the drive)")
    return written
