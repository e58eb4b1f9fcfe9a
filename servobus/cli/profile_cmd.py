"""``servobus profile``: the point-to-point profile table (DYN2 7.4.1 / DYN5 Appendix B).

Computed by the family's ``Family.ptp_profile`` (the family of the drive the global options
name; ``sim://`` when none), the same code its virtual drive runs. The CLI names no family:
the options are parameters by name, checked against that family's table at parse time.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, TypeAlias

import click

from servobus.axis.types import Family, PtpCalculator
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.param_types import family_for
from servobus.errors import ArgumentRangeError, NotSupported

if TYPE_CHECKING:
    _IntType: TypeAlias = click.ParamType[int]
else:
    _IntType = click.ParamType

def calculator(family: Family | None) -> tuple[Family, PtpCalculator]:
    """The family and its profile calculator; NotSupported where it has none."""
    if family is None:
        raise NotSupported("this drive's family is unknown before connecting: give a drive "
                           "URL of a family with a point-to-point profile table (DMM)")
    if family.ptp_profile is None:
        raise NotSupported(f"{family.title} drives have no point-to-point profile table",
                           family=family.name)
    return family, family.ptp_profile


class FamilyParam(_IntType):
    """An integer within the range of the family parameter ``param`` (the family of the
    global options' drive), refused at parse time."""

    name = "integer"

    def __init__(self, param: str) -> None:
        self.param = param

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> int:
        if isinstance(value, int) and not isinstance(value, bool):
            number = value
        else:
            try:
                number = int(str(value), 10)
            except ValueError:
                self.fail(f"{value!r} is not an integer", param, ctx)
        family = family_for(ctx.find_object(CliContext) if ctx is not None else None)
        if family is None or family.ptp_profile is None:
            return number  # the command says why there is no table
        try:
            return family.param(self.param).check(number)
        except ArgumentRangeError as exc:
            self.fail(str(exc), param, ctx)


@click.command("profile", cls=ServobusCommand)
@click.option("--max-speed", type=FamilyParam("max_speed"), default=None,
              help="Max Speed parameter (MaxSpd) [default: the parameter's default]")
@click.option("--max-accel", type=FamilyParam("max_accel"), default=None,
              help="Max Accel parameter (MaxAcl) [default: the parameter's default]")
@click.option("--gear", "gear_num", type=FamilyParam("gear_num"), default=None,
              help="GEAR_NUM parameter [default: the parameter's default]")
@click.argument("command", type=click.IntRange(-134_217_728, 134_217_727))
@pass_cli
def profile_command(cli: CliContext, max_speed: int | None, max_accel: int | None,
                    gear_num: int | None, command: int) -> None:
    """Speeds, acceleration, times and distances of a point-to-point move of COMMAND units."""
    family, ptp = calculator(family_for(cli))
    given = {"max_speed": max_speed, "max_accel": max_accel, "gear_num": gear_num}
    values: dict[str, int] = {}
    for name in ptp.inputs:
        value = given.get(name)
        if value is None:
            value = family.param(name).default
        if value is None:
            raise ArgumentRangeError(f"{name} has no default on {family.title}: give it")
        values[name] = value
    prof = ptp.compute(values, command)
    if cli.json:
        click.echo(json.dumps(prof.as_dict(), indent=1))
        return
    words = {"max_speed": "MaxSpd", "max_accel": "MaxAcl", "gear_num": "GEAR_NUM"}
    click.echo(" ".join(f"{words.get(k, k)}={v}" for k, v in values.items())
               + f" command={command}")
    rows = prof.rows()
    width = max(len(label) for label, _ in rows)
    for label, text in rows:
        click.echo(f"  {label:<{width}}  {text}")


def register(group: click.Group) -> None:
    group.add_command(profile_command)
