"""``origin`` and ``home``: where the axis counts from, on a drive or a machine axis.

``origin`` makes the position where the motor stands 0, the family's own way
(AsyncAxis.set_origin: DMM Set_Origin, DYN5 Set ABS Origin, YZ-AIM's position clear), and
reads the position back. On a machine axis the soft limits count from it.

``home`` starts the drive's own homing (AsyncAxis.home) and waits until the drive reports
it done; where the family's drive has no homing a host can start, one line says why and
nothing is sent (docs/cli.md, "home": DMM DYN2/DYN4 in absolute mode home to their stored
zero; the DYN5 and the YZ-AIM motors have none a host starts). Ctrl-C or SIGTERM during
the wait stops the motor.
"""

from __future__ import annotations

import time

import click
from rich.console import Console

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.one_axis import POLL_S, Opened, open_one
from servobus.cli.output import emit
from servobus.cli.param_types import Seconds
from servobus.errors import DriveTimeout


@click.command("origin", cls=ServobusCommand)
@pass_cli
def origin_cmd(ctx: CliContext) -> None:
    """Set the position where the motor stands as zero (the drive family's own way).

    On a machine axis (--machine/--axis) the soft limits count from it."""
    with open_one(ctx) as one:
        before, was = one.where(), one.position()
        one.axis.set_origin()
        after, now = one.where(), one.position()
    record = {**one.key, "origin_set": True, "position_before": was, "position": now,
              "unit": one.unit}

    def render(con: Console) -> None:
        limits = "; the soft limits count from it" if "axis" in one.key else ""
        con.print(f"{one.who}: origin set where it stands (it read {before}, now {after})"
                  f"{limits}", markup=False)

    emit(ctx, record, render)


@click.command("home", cls=ServobusCommand)
@click.option("--wait-timeout", type=Seconds(), default=30.0, show_default=True,
              help="seconds to wait for the homing to end")
@pass_cli
def home_cmd(ctx: CliContext, wait_timeout: float) -> None:
    """Run the drive's own homing and wait until it ends.

    Where the drive has no homing a host can start, one line says why (exit 2) and
    nothing is sent: set the zero where the axis stands with `servobus origin`."""
    with open_one(ctx) as one, stop_on_interrupt(one.axis):
        one.axis.home()
        _wait_homed(one, wait_timeout)
        where, position = one.where(), one.position()
    record = {**one.key, "homed": True, "position": position, "unit": one.unit}
    emit(ctx, record, lambda con: con.print(f"{one.who}: homed, at {where}", markup=False))


def _wait_homed(one: Opened, timeout: float) -> None:
    """wait_idle until ``timeout``. A drive that restarts for its homing (a DMM drive homes
    after a power-on reset) may not answer at first: its read timeouts are waited out."""
    deadline = time.monotonic() + timeout
    while True:
        remaining = deadline - time.monotonic()
        try:
            one.axis.wait_idle(max(remaining, POLL_S))
            return
        except DriveTimeout as exc:
            if time.monotonic() >= deadline:
                raise CliError(f"{one.who}: the homing did not end within {timeout:g} s "
                               f"({exc})", "give it longer (--wait-timeout), or check the "
                               "drive (`servobus status`)", EXIT_FAULT) from exc


def register(group: click.Group) -> None:
    for command in (origin_cmd, home_cmd):
        group.add_command(command)
