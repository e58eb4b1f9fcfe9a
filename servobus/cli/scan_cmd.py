"""``servobus scan``: which drive ids answer on the line (or CAN bus).

One status read per id with a short deadline and no retry (``Axis.ping``), so a scan of the
64 ids 0..63 takes at most about 64 x ``--per-id`` seconds. On DYN CAN id 0 is the broadcast
id, so the default range starts at 1 there.
"""

from __future__ import annotations

import sys

import click
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.open_axis import connection_label, console, emit, open_axis
from servobus.cli.param_types import Seconds
from servobus.codec.dyn232 import MAX_DRIVE_ID


@click.command("scan", cls=ServobusCommand)
@click.option("--first", type=click.IntRange(0, MAX_DRIVE_ID), default=None,
              help="first id (default 0; 1 on CAN)")
@click.option("--last", type=click.IntRange(0, MAX_DRIVE_ID), default=MAX_DRIVE_ID,
              show_default=True, help="last id")
@click.option("--per-id", "per_id", type=Seconds(maximum=5.0), default=0.05,
              show_default=True, help="seconds to wait for each id's reply")
@pass_cli
def scan_cmd(ctx: CliContext, first: int | None, last: int, per_id: float) -> None:
    """Find the drive ids that answer (one status read per id, no retries)."""
    start = (1 if ctx.can else 0) if first is None else first
    if start > last:
        raise click.BadParameter(f"--first {start} is after --last {last}")
    ids = range(start, last + 1)
    found: list[int] = []
    quiet = ctx.json or not sys.stderr.isatty()
    with open_axis(ctx, drive_id=start) as axis, Progress(
        TextColumn("scanning id {task.fields[current]:>2}"), BarColumn(), MofNCompleteColumn(),
        TextColumn("found {task.fields[found]}"),
        console=console(err=True), transient=True, disable=quiet,
    ) as progress:
        task = progress.add_task("scan", total=len(ids), current=start, found=0)
        for drive_id in ids:
            progress.update(task, current=drive_id)
            if axis.sibling(drive_id).ping(timeout=per_id):
                found.append(drive_id)
            progress.update(task, advance=1, found=len(found))

    def render(con: object) -> None:
        where = connection_label(ctx).rsplit(", id", 1)[0]
        if found:
            click.echo(f"found {len(found)} drive(s) on {where}: {' '.join(map(str, found))}")
        else:
            click.echo(f"no drive answered on {where} (ids {start}..{last})")

    emit(ctx, found, render)


def register(group: click.Group) -> None:
    group.add_command(scan_cmd)
