"""The component's pins, as data (docs/linuxcnc.md, "Pins"): one table read by the
component that makes them and by the docs test that lists them."""

from __future__ import annotations

from collections.abc import MutableMapping
from dataclasses import dataclass
from typing import Literal

Kind = Literal["float", "bit", "s32"]
Direction = Literal["in", "out"]

#: A pin's value as the ``hal`` module hands it over (``comp["x"]``).
Value = float | bool | int
#: What the bridge reads and writes: the ``hal`` component (``comp[name]``), or a dict.
Pins = MutableMapping[str, Value]


@dataclass(frozen=True)
class Pin:
    name: str
    kind: Kind
    direction: Direction
    meaning: str


AXIS_PINS: tuple[Pin, ...] = (
    Pin("position-fb", "float", "out", "position, the axis's unit"),
    Pin("velocity-fb", "float", "out", "speed, the axis's unit per second"),
    Pin("current", "float", "out", "motor current, A"),
    Pin("following-error", "float", "out",
        "position: position-cmd minus position-fb; monitor: the drive's own report where it "
        "gives one, else 0"),
    Pin("enabled", "bit", "out", "the drive's servo is on"),
    Pin("moving", "bit", "out", "a motion runs"),
    Pin("in-position", "bit", "out", "on target, within the drive's window"),
    Pin("online", "bit", "out", "the link answers"),
    Pin("fault", "bit", "out", "alarm, offline, a refused command step, or the watchdog"),
    Pin("alarm-code", "s32", "out", "the drive's alarm code, 0 = none (the family's numbering)"),
    Pin("enable", "bit", "in", "rising edge: servo on (position: streaming starts); falling "
        "edge: stop (position) and servo off"),
    Pin("fault-reset", "bit", "in", "rising edge: clear the drive's alarm and the latched "
        "faults"),
    Pin("position-cmd", "float", "in", "position: the target streamed to the drive"),
)

COMPONENT_PINS: tuple[Pin, ...] = (
    Pin("fault", "bit", "out", "any axis faulted or offline, or the watchdog starved"),
    Pin("watchdog", "bit", "in", "a bit LinuxCNC toggles; without a toggle for --watchdog "
        "seconds every position axis stops"),
)


def axis_pin(axis: str, pin: str) -> str:
    """The pin's name below the component: ``c.position-fb`` (HAL adds ``servobus.``)."""
    return f"{axis}.{pin}"
