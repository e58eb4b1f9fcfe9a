"""Drive commands: ``status``, ``position``, ``speed RPM``, ``move [--relative] TARGET``, ``stop``.

Units are the Axis's, the same on every drive: ``move`` takes encoder counts of the drive
family (``move 16384``), revolutions (``2.5rev``), degrees (``90deg``) or the drive's raw
command units (``120cmd``, where the protocol has them); ``position`` prints counts and
revolutions. Negative numbers are arguments: ``servobus move --relative -120``.
Ctrl-C or SIGTERM during ``move --wait`` stops the motor first (servobus.cli.motion_guard).

Note: without a drive URL each invocation starts its own built-in virtual drive, so state
(position, motion) does not carry over from one command to the next.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any, TypeAlias

import click
from rich.console import Console

from servobus.cli import machine_cli
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import connection_label, emit, kv_text, open_axis
from servobus.cli.param_types import Seconds
from servobus.errors import NotSupported

if TYPE_CHECKING:
    from servobus.axis.sync import Axis
    from servobus.families.base import AxisStatus

    _TargetType: TypeAlias = click.ParamType[tuple[float, str]]
else:
    _TargetType = click.ParamType

_TARGET = re.compile(r"^([-+]?\d+(?:\.\d*)?|[-+]?\.\d+)\s*(counts?|rev|revs|deg|cmd|mm)?$")


class Target(_TargetType):
    """``16384``, ``-2.5rev``, ``90deg``, ``120cmd`` -> (number, unit)."""

    name = "target"

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> tuple[float, str]:
        if isinstance(value, tuple):
            return value
        match = _TARGET.match(str(value).strip().lower())
        if match is None:
            self.fail(f"{value!r}: write counts (16384), revolutions (2.5rev), degrees (90deg) "
                      "or command units (120cmd)", param, ctx)
        number, unit = float(match.group(1)), (match.group(2) or "").rstrip("s")
        unit = {"count": "counts", "rev": "rev"}.get(unit, unit)
        return number, unit  # "" = bare: counts on a drive, the axis's unit on a machine


def check_drive_target(number: float, unit: str) -> None:
    """A TARGET for a single drive (no machine): whole counts, no mm (nothing is opened)."""
    if unit in ("", "counts", "cmd") and not number.is_integer():
        raise click.BadParameter(f"{number:g}: {unit or 'counts'} are whole numbers",
                                 param_hint="TARGET")
    if unit == "mm":
        raise click.BadParameter("mm needs a machine file that gives the axis's mechanics "
                                 "(--machine FILE, docs/machine.md)", param_hint="TARGET")


def to_counts(axis: Axis, number: float, unit: str) -> int:
    if unit == "rev":
        return int(axis.revs(number))
    if unit == "deg":
        return int(axis.degrees(number))
    return int(number)


def status_record(axis: Axis, status: AxisStatus) -> dict[str, object]:
    """--json of ``status``: the AxisStatus at top level, position, the vendor's extras."""
    record: dict[str, object] = {"drive_id": axis.drive_id, "protocol": axis.protocol,
                                 **status.as_dict(), "position": axis.position()}
    vendor: Any = status.vendor
    if vendor is not None and hasattr(vendor, "as_dict"):
        record["vendor_status"] = vendor.as_dict()
    if "config" in axis.family.features and hasattr(axis.core, "config"):
        record["config"] = axis.config().as_dict()
    return record


def render_status(con: Console, record: dict[str, object], title: str) -> None:
    nested = ("config", "vendor_status")
    top = {k: v for k, v in record.items() if k not in (*nested, "drive_id", "protocol")}
    if top.get("alarm") == "":  # people read an empty field as "not read"
        top["alarm"] = "none"
    con.print(kv_text(title, top), markup=False)
    for key in nested:
        block = record.get(key)
        if isinstance(block, dict):
            con.print(kv_text(key.replace("_", " "), block), markup=False)


@click.command("status", cls=ServobusCommand)
@pass_cli
def status_cmd(ctx: CliContext) -> None:
    """Decoded drive status (and the drive's configuration where it has one)."""
    if ctx.machine_mode:  # one table of every axis, or the one --axis names
        machine_cli.status(ctx)
        return
    with open_axis(ctx) as axis:
        record = status_record(axis, axis.status())
        label = connection_label(ctx, axis)
    emit(ctx, record, lambda con: render_status(con, record, f"status of {label}"))


@click.command("position", cls=ServobusCommand)
@pass_cli
def position_cmd(ctx: CliContext) -> None:
    """Absolute position in encoder counts (and revolutions) of the drive family."""
    if ctx.machine_mode:  # in the axis's unit and counts
        machine_cli.position(ctx)
        return
    with open_axis(ctx) as axis:
        pos, per_rev = axis.position(), axis.counts_per_rev
    emit(ctx, {"position": pos, "counts_per_rev": per_rev, "rev": pos / per_rev},
         lambda con: con.print(f"{pos} counts ({pos / per_rev:.4f} rev)"))


@click.command("speed", cls=ServobusCommand)
@click.argument("rpm", type=float)
@pass_cli
def speed_cmd(ctx: CliContext, rpm: float) -> None:
    """Turn at constant speed RPM (positive = towards increasing position; 0 ramps down).

    On a machine axis (--machine/--axis) the speed is in its unit per second (mm/s, deg/s)."""
    if ctx.machine_mode:
        machine_cli.speed(ctx, rpm)
        return
    if not rpm.is_integer():
        raise click.BadParameter(f"{rpm:g} is not a whole number of rpm", param_hint="RPM")
    rpm = int(rpm)
    with open_axis(ctx) as axis:
        axis.turn(rpm)
    emit(ctx, {"speed_command": rpm}, lambda con: con.print(f"turning at {rpm} rpm"))


@click.command("move", cls=ServobusCommand)
@click.option("--relative", is_flag=True, help="move by TARGET instead of to TARGET")
@click.option("--wait", is_flag=True, help="wait until the move is finished and on position")
@click.option("--wait-timeout", type=Seconds(allow_zero=True), default=30.0, show_default=True,
              help="seconds --wait waits before DriveTimeout")
@click.option("--confirm", is_flag=True,
              help="check that the drive took the move (status/position); never re-sent")
@click.argument("target", type=Target(), metavar="TARGET")
@pass_cli
def move_cmd(ctx: CliContext, relative: bool, wait: bool, wait_timeout: float, confirm: bool,
             target: tuple[float, str]) -> None:
    """Point-to-point move to/by TARGET: counts (16384), 2.5rev, 90deg or 120cmd.

    On a machine axis (--machine/--axis) a bare number is in the axis's unit (12.5 = 12.5 mm),
    checked against its soft limits before anything is sent."""
    number, unit = target
    if ctx.machine_mode:
        machine_cli.move(ctx, f"{number!r}{unit}", relative, wait, wait_timeout)
        return
    check_drive_target(number, unit)
    with open_axis(ctx) as axis, stop_on_interrupt(axis):
        if unit == "cmd":
            if not hasattr(axis.core, "move_to_command"):
                raise NotSupported(f"{axis.family.title} over {axis.protocol} has no raw "
                                   "command units; give counts, rev or deg", axis.family.name)
            (axis.move_by_command if relative else axis.move_to_command)(int(number))
            record: dict[str, object] = {"command_units": int(number)}
        else:
            counts = to_counts(axis, number, unit)
            (axis.move_by if relative else axis.move_to)(counts, confirm=confirm)
            record = {"counts": counts}
        record["move"] = "relative" if relative else "absolute"
        if wait:
            status = axis.wait_idle(timeout=wait_timeout) if wait_timeout > 0 else axis.status()
            record.update(in_position=status.in_position, position=axis.position())

    def render(con: Console) -> None:
        verb = "moving by" if relative else "moving to"
        what = f"{int(number)} command units" if unit == "cmd" else f"{record['counts']} counts"
        con.print(f"{verb} {what}" + (f"; done at {record['position']} counts" if wait else ""))

    emit(ctx, record, render)


@click.command("stop", cls=ServobusCommand)
@pass_cli
def stop_cmd(ctx: CliContext) -> None:
    """Stop: ramp down at the drive's deceleration and hold position."""
    if ctx.machine_mode:
        machine_cli.stop(ctx)
        return
    with open_axis(ctx) as axis:
        axis.stop()
    emit(ctx, {"stopped": True}, lambda con: con.print("stopping"))


def register(group: click.Group) -> None:
    for command in (status_cmd, position_cmd, speed_cmd, move_cmd, stop_cmd):
        group.add_command(command)
