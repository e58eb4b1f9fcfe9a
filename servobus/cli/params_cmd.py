"""``servobus params`` (show / --save / --load / --diff) and ``servobus set NAME VALUE``.

Decisions: ``--load`` writes only the parameters whose value differs from the drive's (each
write costs an EEPROM cycle) and reads them back to confirm; ``--diff`` exits with status 1
when the drive differs from the file (like ``diff``). ``--json params`` prints the backup
format itself, so ``servobus --json params > backup.json`` is a valid backup. Files are
validated before any connection is opened.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import click
from rich.console import Console
from rich.table import Table

from servobus.axis.types import Family
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import EXIT_DIFFERENT, EXIT_FAULT, CliError
from servobus.cli.open_axis import open_axis
from servobus.cli.output import console, emit, emit_json, note
from servobus.cli.param_types import ReachableParam, family_for, reachable_help
from servobus.families import family
from servobus.families import params_file as PF

if TYPE_CHECKING:
    from servobus.axis.sync import Axis


def params_table(values: dict[str, int], title: str, width: int, fam: Family) -> Table:
    """Parameter table; the explanation column only when the terminal is wide enough."""
    wide = width >= 110
    table = Table(title=title, title_justify="left")
    table.add_column("parameter", style="bold")
    table.add_column("value", justify="right")
    table.add_column("range", justify="right")
    table.add_column("unit")
    if wide:
        table.add_column("meaning")
    for name, value in values.items():
        s = fam.param(name)
        cells = [name, str(value), f"{s.minimum}..{s.maximum}", s.unit]
        table.add_row(*cells, *([s.doc] if wide else []))
    return table


def _show(ctx: CliContext) -> None:
    with open_axis(ctx) as axis:
        values = axis.read_params()
        backup = PF.ParamsBackup(axis.protocol, axis.drive_id, dict(values), axis.family.name)
        fam = axis.family
    emit(ctx, backup.to_json(),
         lambda con: con.print(params_table(backup.params,
                                            f"parameters of drive {backup.drive_id}",
                                            con.width, fam)))


def _save(ctx: CliContext, path: str) -> None:
    with open_axis(ctx) as axis:
        values = axis.read_params()
        backup = PF.ParamsBackup(axis.protocol, axis.drive_id, dict(values), axis.family.name)
    PF.save(path, backup)
    emit(ctx, {"saved": path, **backup.to_json()},
         lambda con: con.print(f"saved {len(values)} parameters of drive {backup.drive_id} "
                               f"({backup.protocol}) to {path}"))


def check_fits(path: str, backup: PF.ParamsBackup, axis: Axis) -> None:
    """Refuse a backup of another family, or with parameters this protocol cannot reach
    (CliError naming both); a note when only the protocol differs (module docstring)."""
    here = f"drive {axis.drive_id} is {axis.family.title} over {axis.protocol}"
    if backup.family != axis.family.name:
        theirs = family(backup.family).title
        raise CliError(f"{path} was saved from a {theirs} drive over {backup.protocol}; {here}",
                       "use a backup of this family (`servobus params --save FILE` makes one)")
    if backup.protocol == axis.protocol:
        return
    reach = {p.name for p in axis.parameters()}
    missing = [name for name in backup.params if name not in reach]
    if missing:
        raise CliError(f"{path} was saved over {backup.protocol}; {here}, which does not "
                       f"reach {', '.join(missing)}",
                       "remove those parameters from the file, or restore over "
                       f"{backup.protocol}")
    note(f"note: {path} was saved over {backup.protocol}; {here} (same family: the "
         "parameters are the same)")


def _load(ctx: CliContext, path: str) -> None:
    backup = PF.load(path)  # validated before anything is opened or sent
    with open_axis(ctx) as axis:
        drive = axis.drive_id
        check_fits(path, backup, axis)
        before = axis.read_params(list(backup.params))
        if backup.drive_id != drive:  # said once the drive answers, not before a failure
            note(f"note: {path} was saved from drive {backup.drive_id}; restoring onto drive "
                 f"{drive}")
        changes = PF.diff(backup.params, before)
        if changes:
            axis.write_params({name: wanted for name, wanted, _ in changes})
        after = axis.read_params(list(backup.params))
    failed = PF.diff(backup.params, after)
    rows = [{"name": n, "before": before[n], "after": after[n], "wanted": v}
            for n, v in backup.params.items()]

    def render(con: Console) -> None:
        table = Table(title=f"restore {path} -> drive {drive}", title_justify="left")
        for col in ("parameter", "before", "after", ""):
            table.add_column(col, justify="left" if col in ("parameter", "") else "right")
        for r in rows:
            state = ("unchanged" if r["before"] == r["wanted"] else
                     "written" if r["after"] == r["wanted"] else "[red]NOT APPLIED[/red]")
            table.add_row(str(r["name"]), str(r["before"]), str(r["after"]), state)
        con.print(table)
        con.print(f"{len(changes)} written, {len(rows) - len(changes)} unchanged")

    emit(ctx, {"restored": path, "written": [n for n, _, _ in changes], "params": rows}, render)
    if failed:
        names = ", ".join(n for n, _, _ in failed)
        raise CliError(f"drive {drive} did not take: {names}",
                       "check the values against the drive's ranges, then retry", EXIT_FAULT)


def _diff(ctx: CliContext, path: str) -> None:
    backup = PF.load(path)
    with open_axis(ctx) as axis:
        drive = axis.drive_id
        check_fits(path, backup, axis)
        actual = axis.read_params(list(backup.params))
    changes = PF.diff(backup.params, actual)
    if ctx.json:
        emit_json({"file": path, "identical": not changes,
                   "differences": [{"name": n, "file": f, "drive": d} for n, f, d in changes]})
    elif changes:
        table = Table(title=f"{path} vs drive {drive}", title_justify="left")
        table.add_column("parameter", style="bold")
        table.add_column("file", justify="right")
        table.add_column("drive", justify="right")
        for name, wanted, have in changes:
            table.add_row(name, str(wanted), str(have))
        console().print(table)
    else:
        click.echo(f"drive {drive} matches {path} ({len(backup.params)} parameters)")
    if changes:
        sys.exit(EXIT_DIFFERENT)


@click.command("params", cls=ServobusCommand)
@click.option("--save", "save_path", metavar="FILE", default=None,
              help="back the parameters up to FILE (JSON)")
@click.option("--load", "load_path", metavar="FILE", default=None,
              help="restore the parameters from FILE (only changed values are written)")
@click.option("--diff", "diff_path", metavar="FILE", default=None,
              help="compare the drive with FILE (exit status 1 when they differ)")
@pass_cli
def params_cmd(ctx: CliContext, save_path: str | None, load_path: str | None,
               diff_path: str | None) -> None:
    """Show the drive's parameters, or back them up / restore / compare them."""
    chosen = [p for p in (save_path, load_path, diff_path) if p is not None]
    if len(chosen) > 1:
        raise click.UsageError("use only one of --save, --load, --diff")
    if save_path is not None:
        _save(ctx, save_path)
    elif load_path is not None:
        _load(ctx, load_path)
    elif diff_path is not None:
        _diff(ctx, diff_path)
    else:
        _show(ctx)


@click.command("set", cls=ServobusCommand,
               help="Write one parameter (checked against its range first) and read it back."
                    f"\n\nNAME is a parameter the protocol can set: {reachable_help()}.")
@click.argument("name", type=ReachableParam(), metavar="NAME")
@click.argument("value", type=int)
@pass_cli
def set_cmd(ctx: CliContext, name: str, value: int) -> None:
    fam = family_for(ctx)
    if fam is not None:
        fam.param(name).check(value)  # ArgumentRangeError before any connection
    with open_axis(ctx) as axis:
        old = axis.read_param(name)
        axis.write_param(name, value)
        new = axis.read_param(name)
    emit(ctx, {"name": name, "old": old, "new": new},
         lambda con: con.print(f"{name}: {old} -> {new}"))
    if new != value:
        raise CliError(f"drive reports {name}={new} after writing {value}",
                       "check the drive's range for this parameter, then retry", EXIT_FAULT)


def register(group: click.Group) -> None:
    group.add_command(params_cmd)
    group.add_command(set_cmd)
