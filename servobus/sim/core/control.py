"""The control channel's language, whatever drive serves it: requests and replies are JSON
objects (:data:`Reply`), a refused request a :class:`ControlError` of one of
:data:`ERROR_KINDS`, a command's or a fault's argument an :class:`Arg` (type, range,
choices, default). The commands and faults a family's virtual drive takes are its own
(``servobus.sim.dmm.control``: JP3 I/O, DMM faults); docs/sim-control.md lists them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from servobus.errors import ServobusError
from servobus.sim.core import loads

Reply = dict[str, Any]


class ControlError(ServobusError):
    """A request the channel refuses; ``kind`` names the class of problem (see ERROR_KINDS)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


#: Error kinds in replies ``{"ok": false, "kind": ..., "error": ...}``.
ERROR_KINDS = {
    "malformed": "the line is not a JSON object",
    "too_long": "the line is longer than the channel accepts (the rest of it is skipped)",
    "unknown_command": "cmd is missing or not a command",
    "unknown_id": "no drive with that id (or id missing with several drives)",
    "bad_argument": "an argument is missing, unknown, of the wrong type or out of range",
    "busy": "the channel serves its maximum number of connections",
}

_REQUIRED = object()


@dataclass(frozen=True)
class Arg:
    """One argument: JSON type (float, int, bool, str), range or choices, default."""

    name: str
    kind: type
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    default: object = _REQUIRED
    doc: str = ""

    @property
    def required(self) -> bool:
        return self.default is _REQUIRED

    def parse(self, raw: object) -> object:
        if self.kind is bool:
            if not isinstance(raw, bool):
                raise ControlError("bad_argument", f"{self.name} must be true or false")
            return raw
        if self.kind is str:
            if not isinstance(raw, str) or (self.choices and raw not in self.choices):
                raise ControlError("bad_argument",
                                   f"{self.name} must be one of {', '.join(self.choices)}")
            return raw
        if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
            raise ControlError("bad_argument", f"{self.name} must be a finite number")
        value: float = raw
        if self.kind is int:
            if value != int(value):
                raise ControlError("bad_argument", f"{self.name} must be an integer")
            value = int(value)
        if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            raise ControlError("bad_argument",
                               f"{self.name} {raw} is outside {self.lo:g}..{self.hi:g}")
        return value


class FaultInfo(Protocol):
    """What a client shows of a fault a channel can inject: name, arguments, what it does."""

    @property
    def name(self) -> str: ...

    @property
    def args(self) -> tuple[Arg, ...]: ...

    @property
    def doc(self) -> str: ...


#: A channel's faults by name.
FaultTable = Mapping[str, FaultInfo]


# ---------------------------------------------------------------------- the load command
#: The ``load`` command's load keys, as in ``sim://`` URLs and ``servobus sim --load ...``
#: (servobus.sim.core.loads): every family's channel takes them.
LOAD_ARGS: tuple[Arg, ...] = (
    Arg("load", str, choices=tuple(loads.PRESETS), default=None,
        doc="a sample load: " + "; ".join(f"{k}: {p.doc}" for k, p in loads.PRESETS.items())),
    Arg("inertia", float, *loads.RANGES["inertia"], default=None,
        doc="load inertia / rotor inertia"),
    Arg("resonance", float, *loads.RANGES["resonance"], default=None,
        doc="resonance of the compliant coupling, Hz (0: rigid)"),
    Arg("load_torque", float, *loads.RANGES["load_torque"], default=None,
        doc="N m on the load side, against + (a weight lifted)"),
)


def load_request(args: Mapping[str, Any]) -> loads.LoadSettings:
    """The load a parsed ``load`` request sets (its :data:`LOAD_ARGS`)."""
    try:
        return loads.load_settings({a.name: args.get(a.name) for a in LOAD_ARGS})
    except ServobusError as exc:
        raise ControlError("bad_argument", str(exc)) from None
