"""Click parameter types that refuse a bad value at parse time, before anything is opened."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, TypeAlias

import click

from servobus.cli.context import CliContext
from servobus.codec import dyn232, dyncan
from servobus.drive import params as P

if TYPE_CHECKING:  # click >= 8.4 types are generic; older ones are not subscriptable at runtime
    _FloatType: TypeAlias = click.ParamType[float]
    _StrType: TypeAlias = click.ParamType[str]
else:
    _FloatType = _StrType = click.ParamType

#: Parameters each protocol can read and write, in the parameter table's order.
REACHABLE_PARAMS: dict[str, tuple[str, ...]] = {
    "DYN232M": tuple(p.name for p in P.PARAMS if p.name in dyn232.PARAM_FUNCTIONS),
    "DYN CAN": tuple(p.name for p in P.PARAMS if p.name in dyncan.PARAM_GROUPS),
}


def protocol_of(ctx: CliContext | None) -> str:
    """The protocol the global options select (``--can`` -> DYN CAN, else DYN232M)."""
    return "DYN CAN" if ctx is not None and ctx.can is not None else "DYN232M"


class Seconds(_FloatType):
    """A finite number of seconds; ``nan``, ``inf`` and values below the minimum are refused.

    ``minimum`` is exclusive unless ``allow_zero`` and the value is 0 (a reply deadline of 0 or
    less could never be met; "wait 0 s" means "check once").
    """

    name = "seconds"

    def __init__(self, *, allow_zero: bool = False, maximum: float | None = None) -> None:
        self.allow_zero = allow_zero
        self.maximum = maximum

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> float:
        if isinstance(value, float | int) and not isinstance(value, bool):
            seconds = float(value)
        else:
            try:
                seconds = float(str(value))
            except ValueError:
                self.fail(f"{value!r} is not a number of seconds", param, ctx)
        if not math.isfinite(seconds):
            self.fail(f"{value} is not a finite number of seconds", param, ctx)
        if seconds < 0 or (seconds == 0 and not self.allow_zero):
            bound = ">= 0" if self.allow_zero else "> 0"
            self.fail(f"{value} s: must be {bound}", param, ctx)
        if self.maximum is not None and seconds > self.maximum:
            self.fail(f"{value} s: must be <= {self.maximum:g}", param, ctx)
        return seconds


class ReachableParam(_StrType):
    """A parameter name the protocol of the global options can actually set."""

    name = "parameter"

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> str:
        protocol = protocol_of(ctx.find_object(CliContext) if ctx is not None else None)
        names = REACHABLE_PARAMS[protocol]
        text = str(value)
        if text in names:
            return text
        if text in P.BY_NAME:
            self.fail(f"{text} is not reachable over {protocol}; choose from: "
                      f"{', '.join(names)}", param, ctx)
        self.fail(f"unknown parameter {text!r}; choose from: {', '.join(names)}", param, ctx)


def reachable_help() -> str:
    """``NAME is one of ...`` per protocol, for help texts."""
    return "; ".join(f"over {proto}: {' '.join(names)}"
                     for proto, names in REACHABLE_PARAMS.items())
