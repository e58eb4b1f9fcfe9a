"""``servobus sim ...``: virtual drive servers. Sub-commands are added by their modules."""

from __future__ import annotations

import copy

import click


@click.group("sim")
def sim_group() -> None:
    """Run virtual drives that speak the real wire protocols."""


def register(group: click.Group) -> None:
    from servobus.cli.sim_control_cmd import control_group

    group.add_command(sim_group)
    sim_group.add_command(control_group)  # the control channel client (no protocol)


def add_sim_command(group: click.Group, command: click.Command,
                    aliases: tuple[str, ...] = ()) -> None:
    """Attach ``servobus sim <command>`` (and hidden ``aliases``); sim_cmd registers first."""
    sim = group.commands.get("sim")
    if not isinstance(sim, click.Group):
        raise RuntimeError(f"servobus.cli.sim_cmd must be registered before sim {command.name}")
    sim.add_command(command)
    for alias in aliases:
        hidden = copy.copy(command)
        hidden.hidden = True
        sim.add_command(hidden, name=alias)
