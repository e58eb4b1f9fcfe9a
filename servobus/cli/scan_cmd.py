"""``servobus scan``: which drive ids answer on the line (or CAN bus, or network).

One status read per id with no retry (``Axis.ping``). The wait per id is the protocol's own
per-attempt reply deadline of a short read (``Axis.ping_deadline``: the request and its reply
on the wire at the link's rate plus the drive's reply time; docs/axis.md, "scan"), or
``--per-id``. So a scan of N ids takes at most about N x that wait: an absent id costs the
whole wait, a present one its reply time.

The default range is every id the protocol addresses (``Axis.drive_ids``); ``--first`` /
``--last`` or ``--ids 1-8,12`` narrow it. Decision on progress: on a terminal, a live bar on
stderr with the ids done, the drives found and the time left; otherwise (a pipe, a log,
``--json``) one stderr line before the scan with its expected duration (ids x the wait per
id; a loaded host adds its own time per id). stdout carries only the result.
"""

from __future__ import annotations

import sys

import click
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeRemainingColumn,
)

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.open_axis import link_url, open_axis
from servobus.cli.output import console, emit, note
from servobus.cli.param_types import Seconds

MAX_ID = 255


def parse_ids(text: str) -> list[int]:
    """``1-8,12`` -> [1, 2, ..., 8, 12] (sorted, each once); BadParameter otherwise."""
    ids: set[int] = set()
    for part in text.split(","):
        low, dash, high = part.strip().partition("-")
        try:
            first, last = int(low), int(high if dash else low)
        except ValueError:
            raise click.BadParameter(f"{text!r}: write ids and ranges, e.g. 1-8,12",
                                     param_hint="--ids") from None
        if not 0 <= first <= last <= MAX_ID:
            raise click.BadParameter(f"{part.strip()!r}: ids are 0..{MAX_ID}, low-high",
                                     param_hint="--ids")
        ids.update(range(first, last + 1))
    return sorted(ids)


def wanted_ids(known: range, first: int | None, last: int | None,
               listed: list[int] | None) -> list[int]:
    """The ids to try, each one the protocol addresses (BadParameter naming its range)."""
    if listed is not None:
        outside = [i for i in listed if i not in known]
        if outside:
            raise click.BadParameter(
                f"{', '.join(map(str, outside))} not in this protocol's ids "
                f"{known.start}..{known.stop - 1}", param_hint="--ids")
        return listed
    start = known.start if first is None else first
    stop = known.stop - 1 if last is None else last
    if start > stop:
        raise click.BadParameter(f"--first {start} is after --last {stop}")
    return list(range(start, stop + 1))


def id_text(ids: list[int]) -> str:
    """[1, 2, 3, 5] -> ``1-3,5``."""
    runs: list[str] = []
    start = prev = ids[0]
    for i in [*ids[1:], None]:
        if i is not None and i == prev + 1:
            prev = i
            continue
        runs.append(str(start) if start == prev else f"{start}-{prev}")
        if i is not None:
            start = prev = i
    return ",".join(runs)


@click.command("scan", cls=ServobusCommand)
@click.option("--first", type=click.IntRange(0, MAX_ID), default=None,
              help="first id [default: the protocol's lowest]")
@click.option("--last", type=click.IntRange(0, MAX_ID), default=None,
              help="last id [default: the protocol's highest]")
@click.option("--ids", "ids_text", metavar="IDS", default=None,
              help="only these ids, e.g. 1-8,12 (instead of --first/--last)")
@click.option("--per-id", "per_id", type=Seconds(maximum=5.0), default=None,
              help="seconds to wait for each id's reply [default: the protocol's reply "
                   "deadline: wire time + the drive's reply time]")
@pass_cli
def scan_cmd(ctx: CliContext, first: int | None, last: int | None, ids_text: str | None,
             per_id: float | None) -> None:
    """Find the drive ids that answer (one status read per id, no retries)."""
    if first is not None and last is not None and first > last:
        raise click.BadParameter(f"--first {first} is after --last {last}")
    if ids_text is not None and (first is not None or last is not None):
        raise click.UsageError("use --ids or --first/--last, not both")
    listed = None if ids_text is None else parse_ids(ids_text)
    found: list[int] = []
    live = not ctx.json and sys.stderr.isatty()
    # Opened as every command opens it (--id, else the protocol's default): the ids are
    # pinged through siblings, and a virtual drive without ?ids= answers at the id it is
    # opened with - so scan finds the drive `status` shows (issue 32), not one at --first.
    with open_axis(ctx) as axis:
        ids = wanted_ids(axis.drive_ids, first, last, listed)
        wait = axis.ping_deadline() if per_id is None else per_id
        where = link_url(ctx)
        if not live:
            note(f"scanning {len(ids)} id(s) ({id_text(ids)}) on {where}: about "
                 f"{len(ids) * wait:.1f} s ({wait * 1000:.0f} ms per absent id)")
        with Progress(
            TextColumn("scanning id {task.fields[current]:>3}"), BarColumn(),
            MofNCompleteColumn(), TextColumn("found {task.fields[found]}"),
            TimeRemainingColumn(), console=console(err=True), transient=True,
            disable=not live,
        ) as progress:
            task = progress.add_task("scan", total=len(ids), current=ids[0], found=0)
            for drive_id in ids:
                progress.update(task, current=drive_id)
                if axis.sibling(drive_id).ping(timeout=wait):
                    found.append(drive_id)
                progress.update(task, advance=1, found=len(found))

    def render(con: object) -> None:
        if found:
            click.echo(f"found {len(found)} drive(s) on {where}: {' '.join(map(str, found))}")
        else:
            click.echo(f"no drive answered on {where} (ids {id_text(ids)})")

    emit(ctx, found, render)


def register(group: click.Group) -> None:
    group.add_command(scan_cmd)
