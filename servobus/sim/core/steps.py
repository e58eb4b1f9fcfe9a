"""Step responses on simulated time: record a simulated core period by period after a command.

The tuning tests (tests/sim/test_tuning.py), tools/plot_steps.py and the table in
docs/tuning.md record their steps here, so all three measure the same thing. No wall clock:
the core runs exactly ``seconds`` of control periods.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from servobus.sim.core import constants as K
from servobus.sim.core.capture import Readouts


class SteppedShaft(Readouts, Protocol):
    """A simulated core with its readouts (the DMM drive, the protocol-free Motor)."""

    time: float

    def advance_to(self, t: float) -> None: ...

    @property
    def shaft_position(self) -> float: ...

    @property
    def load_position(self) -> float: ...


@dataclass
class StepTrace:
    """One sample per control period from the command on: times (s since the command),
    motor and load positions (counts), position error (counts), speed (rpm), current (A)."""

    times: list[float] = field(default_factory=list)
    position: list[float] = field(default_factory=list)
    load_position: list[float] = field(default_factory=list)
    error: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    current: list[float] = field(default_factory=list)


def record(core: SteppedShaft, command: Callable[[], object], seconds: float) -> StepTrace:
    """Run ``command`` now, then ``seconds`` of control periods, sampling after each."""
    trace = StepTrace()
    command()
    start = core.time
    for k in range(1, round(seconds * K.CONTROL_HZ) + 1):
        core.advance_to(start + k * K.CONTROL_DT)
        trace.times.append(k * K.CONTROL_DT)
        trace.position.append(core.shaft_position)
        trace.load_position.append(core.load_position)
        trace.error.append(core.position_error)
        trace.speed.append(core.speed_rpm)
        trace.current.append(core.current_a)
    return trace
