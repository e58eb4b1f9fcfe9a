"""Click parameter types that refuse a bad value at parse time, before anything is opened."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, TypeAlias

import click

from servobus.cli.context import CliContext

if TYPE_CHECKING:
    from servobus.axis.types import Family

if TYPE_CHECKING:  # click >= 8.4 types are generic; older ones are not subscriptable at runtime
    _FloatType: TypeAlias = click.ParamType[float]
    _StrType: TypeAlias = click.ParamType[str]
else:
    _FloatType = _StrType = click.ParamType



def reachable_params() -> dict[str, tuple[str, ...]]:
    """Protocol -> the parameter names it can read and write (each package's ``PARAMS``)."""
    from servobus.axis import registry

    return {name: tuple(registry.load(target))
            for name, target in registry.provided("PARAMS").items()}


def family_for(ctx: CliContext | None) -> Family | None:
    """The device family of the drive the global options name, known before connecting."""
    from servobus.axis import registry
    from servobus.families import family

    protocol = protocol_of(ctx)
    name = registry.provided("FAMILIES").get(protocol or "")
    return None if name is None else family(name)


def protocol_of(ctx: CliContext | None) -> str | None:
    """The protocol of the drive the global options name (the built-in one when none)."""
    from servobus.axis import registry
    from servobus.axis.url import parse_url

    url = ctx.url if ctx is not None else parse_url("sim://").raw
    try:
        return registry.protocol_of(parse_url(url))
    except ValueError:  # a malformed URL: the connection reports it
        return None


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
        table = reachable_params()
        text = str(value)
        if protocol not in table:
            return text  # checked by the Axis once connected
        names = table[protocol]
        if text in names:
            return text
        fam = family_for(ctx.find_object(CliContext) if ctx is not None else None)
        in_family = fam is not None and any(p.name == text for p in fam.params)
        if in_family or any(text in other for other in table.values()):
            self.fail(f"{text} is not reachable over {protocol}; choose from: "
                      f"{', '.join(names)}", param, ctx)
        self.fail(f"unknown parameter {text!r}; choose from: {', '.join(names)}", param, ctx)


def reachable_help() -> str:
    """``over PROTOCOL: NAME ...`` per protocol, for help texts."""
    return "; ".join(f"over {proto}: {' '.join(names)}"
                     for proto, names in reachable_params().items())
