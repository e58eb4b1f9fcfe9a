"""The check of LinuxCNC's position command against the machine file's ``speed`` and
``accel`` (maxima), before a target reaches the drive (docs/linuxcnc.md, "position").

A userspace component samples ``position-cmd`` whenever its loop runs, not at LinuxCNC's
servo period, so each sample's time is known to within a servo period or so. Decisions:

* speed: a step from the last target to this one over ``dt`` seconds is refused when it is
  longer than ``speed x (dt + SLACK_S)`` (``SLACK_S`` absorbs the sampling time's
  uncertainty: a few servo periods);
* acceleration: velocities are taken over windows of at least ``WINDOW_S`` (differences of
  single samples would be noise), and a change between two windows larger than
  ``accel x (the time between their middles + SLACK_S)`` is refused;
* the first target after ``enable`` may stand at most ``speed x JOIN_S`` from the motor
  (LinuxCNC holds a disabled joint's command at its feedback, so it starts where the motor
  stands).
"""

from __future__ import annotations

from dataclasses import dataclass

SLACK_S = 0.01
WINDOW_S = 0.05
JOIN_S = 0.05


class StepRefused(Exception):
    """The command asks more than the machine file allows; nothing was sent."""


@dataclass
class StepGuard:
    """Checks one axis's command stream; ``speed``/``accel`` in user units (/s, /s²)."""

    speed: float
    accel: float
    unit: str = ""
    _last: tuple[float, float] | None = None  # (time, target) of the last accepted target
    _window: tuple[float, float] | None = None  # (time, target) where this window began
    _velocity: tuple[float, float] | None = None  # (middle time, velocity) of the last window

    def join(self, now: float, target: float, motor: float) -> None:
        """The first target after enable: near the motor, else StepRefused."""
        if abs(target - motor) > self.speed * JOIN_S:
            raise StepRefused(
                f"position-cmd {target:g} {self.unit} is {abs(target - motor):g} {self.unit} "
                f"from the motor at enable (at most {self.speed * JOIN_S:g}: speed x "
                f"{JOIN_S:g} s)")
        self._last = (now, target)
        self._window = (now, target)
        self._velocity = None

    def check(self, now: float, target: float) -> float:
        """The speed the step asks (user units per second), or StepRefused."""
        if self._last is None:
            raise StepRefused("no target accepted since enable")
        then, last = self._last
        dt = max(now - then, 0.0)
        if abs(target - last) > self.speed * (dt + SLACK_S):
            raise StepRefused(
                f"position-cmd stepped {abs(target - last):g} {self.unit} in {dt * 1000:.1f} "
                f"ms: above speed {self.speed:g} {self.unit}/s")
        self._check_accel(now, target)
        self._last = (now, target)
        return (target - last) / dt if dt > 0 else 0.0

    def _check_accel(self, now: float, target: float) -> None:
        assert self._window is not None
        start, origin = self._window
        if now - start < WINDOW_S:
            return
        middle = (start + now) / 2
        velocity = (target - origin) / (now - start)
        if self._velocity is not None:
            before_middle, before = self._velocity
            allowed = self.accel * (middle - before_middle + SLACK_S)
            if abs(velocity - before) > allowed:
                raise StepRefused(
                    f"position-cmd changed speed by {abs(velocity - before):g} {self.unit}/s "
                    f"in {(middle - before_middle) * 1000:.0f} ms: above accel "
                    f"{self.accel:g} {self.unit}/s^2")
        self._velocity = (middle, velocity)
        self._window = (now, target)
