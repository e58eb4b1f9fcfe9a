"""``servobus scan``: which drive ids answer on the line (or CAN bus).

One status read per id with a short deadline and no retry (``Axis.ping``), so a scan of
N ids takes at most about N x ``--per-id`` seconds. The default range is every id the
protocol addresses (``Axis.drive_ids``: DYN232M 0..63; DYN CAN 1..63, 0 being broadcast).
"""

from __future__ import annotations

import sys

import click
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.open_axis import connection_label, console, emit, open_axis
from servobus.cli.param_types import Seconds


@click.command("scan", cls=ServobusCommand)
@click.option("--first", type=click.IntRange(0, 255), default=None,
              help="first id [default: the protocol's lowest]")
@click.option("--last", type=click.IntRange(0, 255), default=None,
              help="last id [default: the protocol's highest]")
@click.option("--per-id", "per_id", type=Seconds(maximum=5.0), default=0.05,
              show_default=True, help="seconds to wait for each id's reply")
@pass_cli
def scan_cmd(ctx: CliContext, first: int | None, last: int | None, per_id: float) -> None:
    """Find the drive ids that answer (one status read per id, no retries)."""
    if first is not None and last is not None and first > last:
        raise click.BadParameter(f"--first {first} is after --last {last}")
    found: list[int] = []
    quiet = ctx.json or not sys.stderr.isatty()
    with open_axis(ctx, drive_id=first) as axis, Progress(
        TextColumn("scanning id {task.fields[current]:>2}"), BarColumn(), MofNCompleteColumn(),
        TextColumn("found {task.fields[found]}"),
        console=console(err=True), transient=True, disable=quiet,
    ) as progress:
        known: range = axis.drive_ids
        start = known.start if first is None else first
        stop = known.stop - 1 if last is None else last
        if start > stop:
            raise click.BadParameter(f"--first {start} is after --last {stop}")
        ids = range(start, stop + 1)
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
            click.echo(f"no drive answered on {where} (ids {ids.start}..{ids.stop - 1})")

    emit(ctx, found, render)


def register(group: click.Group) -> None:
    group.add_command(scan_cmd)
