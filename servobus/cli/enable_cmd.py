"""``enable`` and ``disable``: servo on and servo off, on a drive or a machine axis.

Each sends the family's own command once (AsyncAxis.enable/disable), then reads the status
until the drive reports the new state, for at most ``--wait-timeout`` seconds: the command
says what the drive shows, not what was asked. A drive still disabled after ``enable``
exits 1: in alarm (latched: ``servobus reset`` clears it), or held off by something the
host cannot override (a hardware enable input).
"""

from __future__ import annotations

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.one_axis import open_one, status_when
from servobus.cli.output import emit
from servobus.cli.param_types import Seconds
from servobus.errors import DriveAlarm

WAIT_HELP = "seconds to wait for the drive to report the new state"


def _switch(ctx: CliContext, on: bool, wait_timeout: float) -> None:
    with open_one(ctx) as one:
        if on:
            one.axis.enable()
        else:
            one.axis.disable()
        status = status_when(one.axis, wait_timeout, enabled=on)
    record = {**one.key, "enabled": status.enabled}
    state = "enabled (servo on)" if status.enabled else "disabled (motor free)"
    emit(ctx, record, lambda con: con.print(f"{one.who} {state}", markup=False))
    if status.enabled == on:
        return
    if status.alarm_latched:
        raise DriveAlarm(f"{one.who} did not enable: alarm {status.alarm_code} "
                         f"{status.alarm_text} (latched)", code=status.alarm_code)
    asked = "enable" if on else "disable"
    raise CliError(f"{one.who} still reports {'disabled' if on else 'enabled'} "
                   f"{wait_timeout:g} s after {asked}",
                   "check the drive's hardware enable input and its status "
                   "(`servobus status`)", EXIT_FAULT)


@click.command("enable", cls=ServobusCommand)
@click.option("--wait-timeout", type=Seconds(), default=2.0, show_default=True, help=WAIT_HELP)
@pass_cli
def enable_cmd(ctx: CliContext, wait_timeout: float) -> None:
    """Servo on: the motor holds its position and takes motion commands.

    Exits 1 when the drive still reports disabled (an alarm: `servobus reset`)."""
    _switch(ctx, True, wait_timeout)


@click.command("disable", cls=ServobusCommand)
@click.option("--wait-timeout", type=Seconds(), default=2.0, show_default=True, help=WAIT_HELP)
@pass_cli
def disable_cmd(ctx: CliContext, wait_timeout: float) -> None:
    """Servo off: the motor is free (a load that gravity pulls falls unless braked).

    A motion in progress stops being driven; `servobus enable` takes the drive back."""
    _switch(ctx, False, wait_timeout)


def register(group: click.Group) -> None:
    for command in (enable_cmd, disable_cmd):
        group.add_command(command)
