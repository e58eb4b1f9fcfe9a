"""A virtual drive's connector I/O, reached from the Axis without importing the simulator.

``AsyncAxis.virtual_io()`` returns a :class:`VirtualIo` for the drive of the axis: what a
machine wires *around* a DMM drive on JP3 (DYN2 manual 2.3, 4.1-4.6) - the analog reference,
a pulse generator, the ENA input - and what the drive's outputs (ALM, ONPOS/BKO, ZRI) read.
A real drive has no such thing: NotSupported. The in-process virtual drives (``sim://``) of
the DMM families get one from :mod:`servobus.sim.schemes` (the simulator's control
vocabulary, docs/sim-control.md), so a GUI or a test can try the analog and pulse servo
modes without hardware.

Decisions: the calls are async (a future implementation may reach a virtual drive's control
channel over TCP); replies are plain JSON-able dicts in the control channel's vocabulary
(docs/sim-control.md: ``outputs`` and ``state`` fields); a refused argument raises
ArgumentRangeError naming it.
"""

from __future__ import annotations

from typing import Any, Protocol


class VirtualIo(Protocol):
    """The JP3 inputs and outputs of one virtual drive."""

    def limits(self) -> dict[str, Any]:
        """Input ranges: ``analog_v`` [lo, hi], ``pulse_rate_hz`` [lo, hi],
        ``pulse_formats`` (names), ``pulse_count`` [lo, hi]."""

    async def set_analog(self, volts: float) -> dict[str, Any]:
        """The analog reference on JP3-2, in volts."""

    async def pulses(self, fmt: str | None, count: int,
                     rate: float | None = None) -> dict[str, Any]:
        """A train of ``count`` signed pulses (+ = CW) at ``rate`` pulses/s in ``fmt``
        (None: the format the drive decodes). The reply says how many the drive took."""

    async def set_enable(self, enabled: bool) -> dict[str, Any]:
        """The ENA input (False: the drive is disabled, the motor coasts)."""

    async def outputs(self) -> dict[str, Any]:
        """The outputs by meaning and as pin levels."""

    async def state(self) -> dict[str, Any]:
        """The drive's internal state (reference, following error, current, inputs, ...)."""


class VirtualIoSource(Protocol):
    """What ``AsyncAxis.io_source`` holds: the virtual I/O of the drives on a connection."""

    def for_drive(self, drive_id: int) -> VirtualIo:
        """The I/O of drive ``drive_id`` (ArgumentRangeError when there is no such drive)."""
