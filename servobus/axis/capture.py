"""Drive-side sample traces: what a drive's capture buffer gives a scope (docs/axis.md).

``AsyncAxis.trace_buffer()`` returns the samples a drive took on its own clock since the
previous call, as one :class:`Capture` in the Axis units. Drives that keep no such trace
raise NotSupported, and a scope polls the Axis instead. The in-process virtual drives
(``sim://``) record every control period (4 kHz) through :mod:`servobus.sim.core.capture`.

Decisions (no manual defines a host-side trace format):

* sample times are the drive's clock mapped onto the host's ``time.monotonic()``, so
  samples of several drives and host events (a command sent) share one time line;
* the first call starts the recording and may return no samples; a source stops recording
  by itself when nobody has read it for a while (it costs the drive's host CPU);
* status is one number per sample whose bits are :data:`STATUS_BITS` (bit 0 first).
"""

from __future__ import annotations

from array import array
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

#: The signals a capture may hold: name -> unit (Axis units).
SIGNALS: Mapping[str, str] = {
    "position": "counts",
    "position_error": "counts",  # commanded reference - actual position
    "speed": "rpm",
    "current": "A",
    "status": "bits",
}
#: Bits of the ``status`` signal, bit 0 first (the AxisStatus fields of the same names;
#: ``alarm`` is alarm_code != 0).
STATUS_BITS: tuple[str, ...] = ("enabled", "moving", "in_position", "alarm")


def status_bits(enabled: bool, moving: bool, in_position: bool, alarm: bool) -> int:
    """The ``status`` sample value of one status (see :data:`STATUS_BITS`)."""
    return int(enabled) | int(moving) << 1 | int(in_position) << 2 | int(alarm) << 3


@dataclass(frozen=True)
class Capture:
    """Evenly spaced samples: sample ``i`` was taken at ``t0 + i / rate_hz``."""

    t0: float  # time.monotonic() seconds of the first sample (drive clock mapped)
    rate_hz: float
    counts_per_rev: int  # of the position signals
    signals: Mapping[str, array[float]] = field(default_factory=dict)
    lost: int = 0  # samples dropped (the buffer overflowed) before this one

    @property
    def count(self) -> int:
        return min((len(v) for v in self.signals.values()), default=0)

    def rescaled(self, counts_per_rev: int) -> Capture:
        """The same samples with positions in ``counts_per_rev`` counts per revolution."""
        if counts_per_rev == self.counts_per_rev:
            return self
        k = counts_per_rev / self.counts_per_rev
        signals = {name: (array("d", (x * k for x in values))
                          if SIGNALS.get(name) == "counts" else values)
                   for name, values in self.signals.items()}
        return Capture(self.t0, self.rate_hz, counts_per_rev, signals, self.lost)


class CaptureSource(Protocol):
    """What ``AsyncAxis.capture_source`` holds: the traces of the drives on a connection."""

    def read(self, drive_id: int) -> Capture:
        """Samples of drive ``drive_id`` since the previous read (starts recording)."""
