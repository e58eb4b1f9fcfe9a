"""Drive commands: ``status``, ``position``, ``speed RPM``, ``move [--relative] COUNT``, ``stop``.

Numbers are the protocol's: ``move`` takes command units (the motor moves
COUNT x 4096 / GEAR_NUM x 4 encoder counts), ``position`` prints encoder counts (65,536/rev).
Negative numbers are arguments: ``servobus move --relative -120`` (``--`` is not needed).
Ctrl-C or SIGTERM during ``move --wait`` stops the motor first (servobus.cli.motion_guard).

Note: without ``--port``/``--can`` each invocation starts its own embedded virtual drive, so
state (position, motion) does not carry over from one command to the next.
"""

from __future__ import annotations

import click
from rich.console import Console

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import connection_label, emit, kv_text, open_axis
from servobus.cli.param_types import Seconds
from servobus.drive.registers import DriveConfig, DriveStatus


def status_record(status: DriveStatus, config: DriveConfig, position: int,
                  drive_id: int, protocol: str) -> dict[str, object]:
    """--json of ``status``: the status bits at top level, the config nested."""
    return {"drive_id": drive_id, "protocol": protocol, **status.as_dict(),
            "position": position, "config": config.as_dict()}


def render_status(con: Console, record: dict[str, object], title: str) -> None:
    status = {k: v for k, v in record.items() if k not in ("config", "drive_id", "protocol")}
    config = record["config"]
    assert isinstance(config, dict)
    con.print(kv_text(title, status), markup=False)
    con.print(kv_text("config", config), markup=False)


@click.command("status", cls=ServobusCommand)
@pass_cli
def status_cmd(ctx: CliContext) -> None:
    """Decoded drive status and configuration."""
    with open_axis(ctx) as axis:
        record = status_record(axis.status(), axis.config(), axis.position(), axis.drive_id,
                               axis.protocol)
    emit(ctx, record, lambda con: render_status(con, record, f"status of {connection_label(ctx)}"))


@click.command("position", cls=ServobusCommand)
@pass_cli
def position_cmd(ctx: CliContext) -> None:
    """Absolute position in encoder counts (65,536 per revolution)."""
    with open_axis(ctx) as axis:
        pos = axis.position()
    emit(ctx, {"position": pos}, lambda con: con.print(f"{pos} counts"))


@click.command("speed", cls=ServobusCommand)
@click.argument("rpm", type=int)
@pass_cli
def speed_cmd(ctx: CliContext, rpm: int) -> None:
    """Turn at constant speed RPM (positive = CW; 0 ramps down and holds)."""
    with open_axis(ctx) as axis:
        axis.turn(rpm)
    emit(ctx, {"speed_command": rpm}, lambda con: con.print(f"turning at {rpm} rpm"))


@click.command("move", cls=ServobusCommand)
@click.option("--relative", is_flag=True, help="move by COUNT instead of to COUNT")
@click.option("--wait", is_flag=True, help="wait until the move is finished and on position")
@click.option("--wait-timeout", type=Seconds(allow_zero=True), default=30.0, show_default=True,
              help="seconds --wait waits before DriveTimeout")
@click.argument("count", type=int)
@pass_cli
def move_cmd(ctx: CliContext, relative: bool, wait: bool, wait_timeout: float,
             count: int) -> None:
    """Point-to-point move (S-curve) to/by COUNT command units."""
    with open_axis(ctx) as axis, stop_on_interrupt(axis):
        if relative:
            axis.move_by(count)
        else:
            axis.move_to(count)
        record: dict[str, object] = {"move": "relative" if relative else "absolute",
                                     "command": count}
        if wait:
            status = axis.wait_idle(timeout=wait_timeout)
            record.update(on_position=status.on_position, position=axis.position())

    def render(con: Console) -> None:
        verb = "moving by" if relative else "moving to"
        con.print(f"{verb} {count}" + (f"; done at {record['position']} counts" if wait else ""))

    emit(ctx, record, render)


@click.command("stop", cls=ServobusCommand)
@pass_cli
def stop_cmd(ctx: CliContext) -> None:
    """Stop: ramp down at Max Accel and hold position."""
    with open_axis(ctx) as axis:
        axis.stop()
    emit(ctx, {"stopped": True}, lambda con: con.print("stopping"))


def register(group: click.Group) -> None:
    for command in (status_cmd, position_cmd, speed_cmd, move_cmd, stop_cmd):
        group.add_command(command)
