"""``servobus sim ...``: virtual drive servers. ``servobus.cli.protocol_cmds`` adds one
sub-command per protocol from the registry; the control channel client is the CLI's own."""

from __future__ import annotations

import click


@click.group("sim")
def sim_group() -> None:
    """Run virtual drives that speak the real wire protocols."""


def register(group: click.Group) -> None:
    from servobus.cli.sim_control_cmd import control_group

    group.add_command(sim_group)
    sim_group.add_command(control_group)  # the control channel client (no protocol)
