"""One test move as the tuner sees it, and what it reads from it: step figures, vibration.

Vibration (decision): the current's RMS about its mean while the motor holds its target
(the last :data:`HOLD_FRACTION` of the record), over the largest current of the move. A
settled servo holds with a steady current (ratio < 0.01 on the virtual drives, the speed
estimate's one-count steps); a loop that buzzes or rings holds with an alternating one
(0.1 - 3 at the unstable gains of docs/tuning.md). Polled samples see the same RMS,
aliased, when the link reads the current; where it does not, the position error's RMS over
the step stands in (:func:`vibration`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from servobus.axis.step_metrics import StepMetrics, step_metrics

#: The part of a record the motor holds its target in (the test move's record is long
#: enough for the move to end before it: :data:`servobus.tune.tuner.RECORD_S`).
HOLD_FRACTION = 0.35


@dataclass(frozen=True)
class Record:
    """Samples of one test move from its command on (times in s since the command).

    ``error`` (reference - actual, counts) and ``current`` (A) are None where the link does
    not give them. ``alarm_code`` is the drive's alarm after the move (0: none)."""

    times: Sequence[float]
    position: Sequence[float]
    error: Sequence[float] | None
    current: Sequence[float] | None
    start: float
    target: float
    alarm_code: int = 0
    alarm_text: str = ""

    def metrics(self, band: float | None = None) -> StepMetrics:
        return step_metrics([0.0, *self.times], [self.start, *self.position], 0.0,
                            self.start, self.target, band=band,
                            position_errors=None if self.error is None
                            else [0.0, *self.error])


def _rms_about_mean(values: Sequence[float]) -> float:
    if not values:
        return 0.0
    mean = sum(values) / len(values)
    return math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))


def vibration(record: Record) -> float:
    """How much the motor shakes while it holds (0 = not at all; see the module doc)."""
    n = len(record.times)
    hold = max(2, round(n * HOLD_FRACTION))
    if record.current is not None and n:
        peak = max(abs(c) for c in record.current) or 1.0
        return _rms_about_mean(record.current[-hold:]) / peak
    # no current: the position's swing about the target while holding, over the step
    step = abs(record.target - record.start) or 1.0
    return _rms_about_mean(record.position[-hold:]) / step * 50.0
