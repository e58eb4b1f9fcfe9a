"""``servobus sim ...``: virtual drive servers. Sub-commands are added by their modules."""

from __future__ import annotations

import click


@click.group("sim")
def sim_group() -> None:
    """Run virtual drives that speak the real wire protocols."""


def register(group: click.Group) -> None:
    group.add_command(sim_group)
