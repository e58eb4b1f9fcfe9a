"""``servobus tune``: the manuals' tuning procedure on the chosen axis (servobus.tune).

The axis is chosen as for ``move`` (a drive URL and id, or ``--machine FILE --axis NAME``).
``--distance`` bounds every test move: they run between where the motor stands and that
far away, in the axis's unit with ``move``'s suffixes (a drive: counts, ``rev``, ``deg``; a
machine axis: its unit), inside the machine's soft limits or the drive's reach, checked
before anything moves. It asks first, naming the axis and the distance (``--yes`` skips).
Ctrl-C stops the motor and writes the kept gains back (the tuner's abort path); so do an
alarm and a vibration beyond ``--vibration-limit``. A run that is killed cannot: its kept
gains stay recorded (servobus.tune.kept), the next run on that drive is refused, and
``--restore`` writes them back. ``--goal`` settling (default) or
stiffness (docs/tuning.md, "The procedure", step 3a). The figures before and after print as a
table (``--json``: the whole result).
"""

from __future__ import annotations

import click
from rich.console import Console
from rich.table import Table

from servobus.axis.units import to_counts
from servobus.cli import machine_cli
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.drive_cmds import Target, check_drive_target
from servobus.cli.failures import CliError
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import open_drive_machine
from servobus.cli.output import emit, note
from servobus.errors import ArgumentRangeError
from servobus.tune import plan
from servobus.tune.tuner import GOALS, Trial, TuneResult


def _ms(s: float | None) -> str:
    return "-" if s is None else f"{s * 1000:.1f}"


def _figures(trial: Trial) -> list[str]:
    return [_ms(trial.rise_s), f"{trial.overshoot_pct:.1f}", _ms(trial.settling_s),
            "-" if trial.following_error is None else f"{trial.following_error:.0f}",
            f"{trial.vibration:.3f}"]


def render_result(con: Console, who: str, result: TuneResult) -> None:
    table = Table(title=f"{who}: tuned in {result.trials} test moves, {result.writes} gain "
                        f"writes ({result.source}, {result.rate_hz:.0f} Hz)")
    for column in ("", "rise ms", "overshoot %", "settling ms", "following error counts",
                   "vibration"):
        table.add_column(column, justify="left" if not column else "right")
    table.add_row("before", *_figures(result.before))
    table.add_row("after", *_figures(result.after))
    con.print(table)
    gains = Table()
    for column in ("gain", "kept", "tuned", "vibrated at"):
        gains.add_column(column, justify="left" if column == "gain" else "right")
    for name, kept in result.original.items():
        found = result.limits_found.get(name)
        gains.add_row(name, str(kept), str(result.tuned[name]),
                      "-" if found is None else str(found))
    con.print(gains)
    if result.inertia_ratio is not None:
        con.print(f"load inertia: {result.inertia_ratio:.1f} x the rotor's")
    elif result.amps_per_accel is not None:
        con.print(f"inertia test: {result.amps_per_accel:.3g} A per rev/s^2 (the motor "
                  "model is not known here: no ratio)")
    con.print(f"gains {result.save_hint}" + ("; saved" if result.saved else ""))
    if result.goal == "settling":
        con.print("goal settling: on a drive that learns its load the loop may be softer "
                  "than the search found (--goal stiffness keeps the stiffer gains)")


@click.command("tune", cls=ServobusCommand)
@click.option("--distance", metavar="D",
              help="test moves between here and D away (move's units; a machine axis: its "
                   "unit); required unless --restore")
@click.option("--yes", is_flag=True, help="do not ask before moving")
@click.option("--save", is_flag=True,
              help="save the tuned gains where the drive saves with a command (YZ-AIM 0x14)")
@click.option("--revert", is_flag=True,
              help="write the kept gains back after the run (measure only)")
@click.option("--poll", is_flag=True,
              help="measure by polling the link even where the drive keeps a trace")
@click.option("--vibration-limit", type=float, default=None, metavar="X",
              help="abort beyond this vibration (hold current RMS / move peak; default 1.5)")
@click.option("--goal", type=click.Choice(GOALS), default="settling", show_default=True,
              help="settling: on a drive that learns its load (DMM), also try the whole "
                   "loop softer where that settles faster; stiffness: keep the stiff gains "
                   "(less give under a load step)")
@click.option("--restore", is_flag=True,
              help="no run: write back the kept gains of a run that was killed before it "
                   "could (nothing moves)")
@pass_cli
def tune_cmd(ctx: CliContext, distance: str | None, yes: bool, save: bool, revert: bool,
             poll: bool, vibration_limit: float | None, goal: str, restore: bool) -> None:
    """Tune the axis's gains: raise them until the motor vibrates, back off, verify."""
    if restore:
        if distance is not None or save or revert:
            raise click.UsageError("--restore runs no test moves: no --distance, --save or "
                                   "--revert")
        _restore(ctx)
        return
    if distance is None:
        raise click.UsageError("Missing option '--distance' (or --restore)")
    if save and revert:
        raise click.UsageError("--save and --revert contradict each other")
    if ctx.machine_mode:
        from servobus.machine import parse_quantity

        parse_quantity(distance, machine_cli.chosen_unit(ctx),
                       axis=machine_cli.chosen_axis(ctx))  # before a link opens
        opened = machine_cli.open_machine_axis(ctx)
    else:
        try:
            number, unit = Target().convert(distance, None, None)
        except click.BadParameter:
            raise click.BadParameter(f"{distance!r}: counts, rev or deg",
                                     param_hint="'--distance'") from None
        check_drive_target(number, unit)
        if unit == "cmd":
            raise click.BadParameter("give counts, rev or deg", param_hint="'--distance'")
        opened = open_drive_machine(ctx)
    with opened as axis:
        core = axis.axis
        assert core is not None  # opened (retry is off: a failure raised)
        if ctx.machine_mode:
            from servobus.machine import parse_quantity

            value, quantity_unit = parse_quantity(distance, axis.unit, axis=axis.name)
            user = axis.to_user(value) if quantity_unit == "counts" else value
            counts = axis.to_counts(user) - axis.to_counts(0.0)
            who, shown = f"axis {axis.name} (drive {core.drive_id})", f"{user:g} {axis.unit}"
        else:
            counts = to_counts(number, unit or "counts", core.counts_per_rev)
            who = f"drive {core.drive_id} ({core.family.title} over {core.protocol})"
            shown = distance
        if counts == 0:
            raise click.BadParameter("the distance must not be zero", param_hint="'--distance'")
        axis.check_target(axis.to_user(axis.counts() + counts))  # LimitError: nothing moved
        profile = core.family.tuning
        try:
            plan.check_save(profile, core.family.title, save)
        except ArgumentRangeError as exc:
            raise click.UsageError(f"--save: {exc}") from None
        if not yes and not click.confirm(plan.question(who, shown), default=False, err=True):
            raise CliError("not tuned: the question was declined", "nothing was moved or "
                           "written; --yes skips the question")
        if (text := plan.write_note(profile)) is not None:
            note(text)
        with stop_on_interrupt(core):
            result = axis.tune(counts, owner="cli", vibration_limit=vibration_limit,
                               trace=not poll, save=save, goal=goal)
            if revert:
                axis.revert_gains(result.original)
    record = {"axis": who, "distance": shown, **result.as_dict(), "reverted": revert}

    def render(con: Console) -> None:
        render_result(con, who, result)
        if revert:
            con.print("reverted: the kept gains are back")

    emit(ctx, record, render)


def _restore(ctx: CliContext) -> None:
    """``--restore``: a killed run's kept gains back (servobus.tune.kept)."""
    opened = machine_cli.open_machine_axis(ctx) if ctx.machine_mode else open_drive_machine(ctx)
    with opened as axis:
        written = axis.restore_gains()

    def render(con: Console) -> None:
        if written:
            con.print("restored: " + ", ".join(f"{k} = {v}" for k, v in written.items()))
        else:
            con.print("restored: the drive already held the kept gains")

    emit(ctx, {"restored": written}, render)


def register(group: click.Group) -> None:
    group.add_command(tune_cmd)
