"""``servobus --machine F move --together x=10 y=20``: absolute moves of several axes
started together (AsyncMachine.move_together, docs/machine.md "move_together and the start
skew").

Every target is checked (names, units, soft limits) before anything is sent; then each
axis gets the file's speed and acceleration (servobus.cli.move_profile), and the moves
start: axes whose drives offer a synchronised start on their link (the Axis's
``sync_group``) are loaded and started by one trigger, the others as close together as
their links allow. The output says which, the start skew measured at the host, and what
the skew at the motors can be beyond it. Ctrl-C or SIGTERM during ``--wait`` stops every
axis of the call.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import click
from rich.console import Console

from servobus.cli import machine_cli
from servobus.cli.context import CliContext
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.move_profile import apply_profile
from servobus.cli.output import emit, fixed

if TYPE_CHECKING:
    from servobus.machine import Machine
    from servobus.machine.machine import TogetherReport

SYNCED = ("started by one trigger: no start skew at the host; each drive starts at its own "
          "next control cycle after the trigger")
UNSYNCED = ("the moves started one after another, as their links allow: the motors' start "
            "skew is at least this; on a shared serial line each later start also waits for "
            "the packets before it on the wire, and where a protocol waits for a drive's "
            "reply the next start follows that reply")


class _StopAll:
    """The machine as a Stoppable (servobus.cli.motion_guard): Ctrl-C stops every axis."""

    def __init__(self, machine: Machine) -> None:
        self._machine = machine

    def stop(self) -> None:
        self._machine.stop_all()


def parse_pairs(pairs: tuple[str, ...]) -> dict[str, str]:
    """``("x=10", "y=20mm")`` -> ``{"x": "10", "y": "20mm"}`` (usage errors, one line)."""
    targets: dict[str, str] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or not name or not text:
            raise click.UsageError(f"{pair!r}: --together takes NAME=TARGET pairs, e.g. "
                                   "x=10 y=20mm")
        if name in targets:
            raise click.UsageError(f"axis {name} is named twice")
        targets[name] = text
    return targets


def check_options(ctx: CliContext, relative: bool, confirm: bool) -> None:
    if ctx.url_given:
        raise click.UsageError("--together moves axes of a machine: give --machine FILE "
                               "(without one: the built-in machine), not a drive URL")
    if ctx.axis_option is not None:
        raise click.UsageError("--together names its axes (NAME=TARGET): drop --axis")
    if relative or confirm:
        raise click.UsageError("--together starts absolute moves: drop "
                               f"{'--relative' if relative else '--confirm'}")


def move_together(ctx: CliContext, pairs: tuple[str, ...], *, relative: bool, wait: bool,
                  wait_timeout: float, confirm: bool) -> None:
    """The ``--together`` form of ``move`` (module docstring)."""
    from servobus.machine import parse_quantity

    check_options(ctx, relative, confirm)
    texts = parse_pairs(pairs)
    source, names = machine_cli.spec_names(ctx)
    unknown = [n for n in texts if n not in names]
    if unknown:
        raise click.UsageError(f"no axis {unknown[0]!r} in {source}; axes: {', '.join(names)}")
    with machine_cli.open_machine_cli(ctx, list(texts)) as machine:
        targets: dict[str, float] = {}
        for name, text in texts.items():
            axis = machine[name]
            number, unit = parse_quantity(text, axis.unit, axis=name)
            targets[name] = axis.check_target(axis.to_user(number) if unit == "counts"
                                              else number)
        written = {name: w for name in targets if (w := apply_profile(machine[name]))}
        with stop_on_interrupt(_StopAll(machine)):
            report = machine.move_together(targets, wait=wait,
                                           timeout=wait_timeout if wait_timeout > 0 else None)
        units = {name: machine[name].unit for name in targets}
        reached = {name: machine[name].position() for name in targets} if wait else {}
    record = together_record(report, targets, units, reached, written)
    emit(ctx, record, lambda con: render(con, record, report))


def together_record(report: TogetherReport, targets: dict[str, float], units: dict[str, str],
                    reached: dict[str, float],
                    written: dict[str, dict[str, int]]) -> dict[str, object]:
    first = min(report.starts.values())
    record: dict[str, object] = {
        "targets": targets, "units": units, **report.as_dict(),
        "skew_ms": report.skew_s * 1000.0,
        "start_offsets_ms": {n: (t - first) * 1000.0 for n, t in report.starts.items()},
        "skew_note": SYNCED if report.synchronised else UNSYNCED,
    }
    if reached:
        record["positions"] = reached
    if written:
        record["profile_written"] = written
    return record


def render(con: Console, record: dict[str, object], report: TogetherReport) -> None:
    targets = record["targets"]
    units = record["units"]
    assert isinstance(targets, dict) and isinstance(units, dict)
    moves = ", ".join(f"{n} to {v:g} {units[n]}" for n, v in targets.items())
    con.print(f"moving together: {moves}", markup=False)
    if report.synchronised:
        con.print(f"start: {', '.join(report.groups[0])} {SYNCED}", markup=False)
    else:
        together = "; ".join(f"{', '.join(g)} started by one trigger" for g in report.groups)
        con.print(f"start skew {report.skew_s * 1000.0:.3f} ms measured at the host"
                  f"{f' ({together})' if together else ''}: {UNSYNCED}", markup=False)
    positions = record.get("positions")
    if isinstance(positions, dict):
        done = ", ".join(f"{n} at {fixed(v, 4)} {units[n]}" for n, v in positions.items())
        con.print(f"done: {done}", markup=False)
