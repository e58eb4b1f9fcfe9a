"""``servobus profile``: the point-to-point profile table (DYN2 7.4.1 / DYN5 Appendix B).

Computed by :mod:`servobus.families.dmm.profile`, the same code the virtual drive runs.
"""

from __future__ import annotations

import json

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.families.dmm import params as P
from servobus.families.dmm.profile import ptp_profile


def _param(name: str) -> click.IntRange:
    spec = P.spec(name)
    return click.IntRange(spec.minimum, spec.maximum)


@click.command("profile", cls=ServobusCommand)
@click.option("--max-speed", type=_param("max_speed"), default=P.spec("max_speed").default,
              show_default=True, help="Max Speed parameter (MaxSpd)")
@click.option("--max-accel", type=_param("max_accel"), default=P.spec("max_accel").default,
              show_default=True, help="Max Accel parameter (MaxAcl)")
@click.option("--gear", "gear_num", type=_param("gear_num"), default=P.spec("gear_num").default,
              show_default=True, help="GEAR_NUM parameter")
@click.argument("command", type=click.IntRange(-134_217_728, 134_217_727))
@pass_cli
def profile_command(cli: CliContext, max_speed: int, max_accel: int, gear_num: int,
                    command: int) -> None:
    """Speeds, acceleration, times and distances of a point-to-point move of COMMAND units."""
    prof = ptp_profile(max_speed, max_accel, gear_num, command)
    if cli.json:
        click.echo(json.dumps(prof.as_dict(), indent=1))
        return
    click.echo(f"MaxSpd={max_speed} MaxAcl={max_accel} GEAR_NUM={gear_num} command={command}")
    rows = prof.rows()
    width = max(len(label) for label, _ in rows)
    for label, value in rows:
        click.echo(f"  {label:<{width}}  {value}")


def register(group: click.Group) -> None:
    group.add_command(profile_command)
