"""The drive commands on a machine file (``--machine FILE --axis NAME``; docs/machine.md).

Decisions:

* A command that acts on one axis opens only that axis's link. On a machine of several axes
  it needs ``--axis``: without it, one line lists the names. ``status`` without ``--axis``
  opens every link and shows one table of every axis (an axis whose link cannot be opened
  shows offline and the command exits 2).
* Positions, distances and speeds are in the axis's unit (``move 12.5`` = 12.5 mm on a mm
  axis; ``12.5mm``, ``100counts`` also work; ``speed 20`` = 20 mm/s). Every move is
  checked against the soft limits before anything is sent (LimitError, exit 2).
* ``speed`` holds the motion while the command runs (servobus.cli.hold: a lease it renews;
  the target never passes the soft limit it heads for): it ends with ``--for SECONDS``,
  Ctrl-C/SIGTERM, or at the limit once the motor rests there, then stops the axis. On a
  ``continuous`` axis it returns at once (open-ended).
* The machine is closed without a stop on success (``move`` without ``--wait`` leaves the
  motor moving, as on a single drive); Ctrl-C/SIGTERM stop the axis (motion_guard).
* ``--axis`` without ``--machine`` and without a drive URL uses the built-in virtual
  machine (servobus.machine.builtin), announced on stderr.
* ``origin = "set"`` / ``"home"`` is not applied by these one-shot commands, and a note on
  stderr says so (issue 28): a command cannot know whether the drive was power-cycled since
  the last one, and applying it at every command zeroed the axis again where it stood (two
  ``move 90deg`` turned 180 deg, ``position`` read 0 after each; a DYN5 resets its servo
  control when its origin is set). The drive keeps the origin it has until a power cycle;
  ``servobus gui --machine FILE``, ``servobus serve`` or a script applies the rule once.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager, suppress
from typing import TYPE_CHECKING

import click
from rich.console import Console

from servobus.cli.context import CliContext
from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.output import emit, fixed, following_words, id_words, kv_text, note
from servobus.errors import DriveAlarm

if TYPE_CHECKING:
    from servobus.axis.sync import Axis
    from servobus.machine import Machine, MachineAxis
    from servobus.machine.config import AxisSpec, MachineSpec

def machine_spec(ctx: CliContext) -> tuple[str, MachineSpec]:
    """The file named (or the built-in machine's source) and its spec; nothing is opened."""
    from servobus.machine.builtin import BUILTIN_SOURCE, builtin_spec
    from servobus.machine.config import load_machine_file

    path = ctx.machine_path
    spec = builtin_spec() if path is None else load_machine_file(path)
    return (BUILTIN_SOURCE if path is None else path), spec


def spec_names(ctx: CliContext) -> tuple[str, list[str]]:
    source, spec = machine_spec(ctx)
    return source, [a.name for a in spec.axes]


def chosen_spec(ctx: CliContext) -> AxisSpec:
    """The file's spec of the axis a command acts on (nothing is opened)."""
    name = chosen_axis(ctx)
    return next(a for a in machine_spec(ctx)[1].axes if a.name == name)


def chosen_unit(ctx: CliContext) -> str:
    """The unit of the axis a command acts on, read from the file (nothing is opened): a
    TARGET or SPEED in another unit is refused before any link opens."""
    return chosen_spec(ctx).unit


def chosen_axis(ctx: CliContext) -> str:
    """The axis a one-axis command acts on: --axis, the only axis, or one line listing them."""
    source, names = spec_names(ctx)
    if ctx.axis_option is not None:
        if ctx.axis_option not in names:
            raise click.UsageError(f"no axis {ctx.axis_option!r} in {source}; axes: "
                                   f"{', '.join(names)}")
        return ctx.axis_option
    if len(names) == 1:
        return names[0]
    raise click.UsageError(f"{source} has axes {', '.join(names)}: give --axis NAME")


@contextmanager
def closed_without_stop(machine: Machine) -> Iterator[None]:
    """``machine`` closed without a stop on the way out: the command stops what it
    started itself. After a failure the close's own errors are dropped (the failure keeps
    its one stderr line)."""
    try:
        yield
    except BaseException:
        with suppress(Exception):
            machine.close(stop=False)
        raise
    machine.close(stop=False)


@contextmanager
def open_machine_cli(ctx: CliContext, only: list[str] | None) -> Iterator[Machine]:
    """Open the machine (only the links of ``only``); close it without a stop on the way out
    (a failure keeps its one stderr line)."""
    from servobus.machine import open_machine

    machine = open_machine(ctx.machine_path, only=only, origins=False)
    note_origins_skipped(machine)
    with closed_without_stop(machine):
        yield machine
    if ctx.machine_path is None:
        note_builtin_machine_once()


@contextmanager
def open_machine_axis(ctx: CliContext) -> Iterator[MachineAxis]:
    name = chosen_axis(ctx)
    with open_machine_cli(ctx, [name]) as machine:
        yield machine[name]


@contextmanager
def open_axis_of_machine(ctx: CliContext) -> Iterator[Axis]:
    """The underlying Axis of the chosen machine axis (params, profile, scan ...)."""
    with open_machine_axis(ctx) as axis:
        core = axis.axis
        assert core is not None  # opened (retry is off: a failure raised)
        yield core


_noted: list[bool] = []


def note_origins_skipped(machine: Machine) -> None:
    """One stderr line naming the origin rules this one-shot command did not apply."""
    rules = [f"{name} (origin = \"{machine.axes[name].core.spec.origin}\")"
             for name in machine.origins_skipped]
    if rules:
        note(f"note: axis {', '.join(rules)}: not applied by a one-shot command, which "
             "cannot tell whether the drive was power-cycled since the last one; positions "
             "and limits count from the drive's own origin (`servobus gui --machine FILE`, "
             "`servobus serve` or a script's open_machine() apply the rule once; "
             "docs/machine.md)")


def note_builtin_machine_once() -> None:
    from servobus.machine.builtin import BUILTIN_NOTE

    if not _noted:
        _noted.append(True)
        note(BUILTIN_NOTE)


def label(axis: MachineAxis) -> str:
    core = axis.axis  # open: the id it talks to, the protocol's default included
    return f"axis {axis.name} ({axis.url}, " \
        f"{id_words(core.drive_id if core is not None else axis.drive_id)})"


# ------------------------------------------------------------------ commands
def axis_record(axis: MachineAxis) -> dict[str, object]:
    """One axis for ``status``: identity, position in the unit and counts, the status."""
    record: dict[str, object] = {"axis": axis.name, "unit": axis.unit, "url": axis.url,
                                 "id": axis.drive_id if axis.axis is None
                                 else axis.axis.drive_id, "online": axis.online,
                                 "limits": list(axis.limits) if axis.limits else None}
    if not axis.online:
        record["error"] = str(axis.last_error or "not opened")
        return record
    counts = axis.counts()
    record.update(protocol=axis.protocol, position=axis.to_user(counts), counts=counts,
                  **axis.status().as_dict())
    core = axis.axis
    error = core.following_error() if core is not None else None
    record["following_error"] = None if error is None else axis.to_user(error)
    return record


def status(ctx: CliContext) -> None:
    if ctx.axis_option is not None:
        with open_machine_axis(ctx) as axis:
            record = axis_record(axis)
            title = f"status of {label(axis)}"
        shown = {**record, "following_error": following_words(record.get("following_error"),
                                                              axis.unit)}
        emit(ctx, record, lambda con: con.print(kv_text(title, shown), markup=False))
        raise_alarms([record])
        return
    from servobus.machine import open_machine

    machine = open_machine(ctx.machine_path, retry=True,  # an unreachable link: offline row
                           origins=False)
    note_origins_skipped(machine)
    try:
        records = [axis_record(a) for a in machine.axes.values()]
        name = machine.name
    finally:
        machine.close(stop=False)
    if ctx.machine_path is None:
        note_builtin_machine_once()
    emit(ctx, {"machine": name, "axes": records},
         lambda con: render_machine_table(con, name, records))
    raise_alarms(records)
    offline = [str(r["axis"]) for r in records if not r["online"]]
    if offline:
        raise CliError(f"axes offline: {', '.join(offline)} "
                       f"({'; '.join(str(r.get('error')) for r in records if not r['online'])})",
                       "check those links (power, cable, URL in the machine file)")


def raise_alarms(records: list[dict[str, object]]) -> None:
    """Exit 1 when an axis shown reports an alarm, as ``status`` of one drive does (after the
    table is printed): DriveAlarm when one is latched, else a notice that needs no reset."""
    alarmed = [r for r in records if r.get("alarm_code")]
    if not alarmed:
        return
    what = "; ".join(f"axis {r['axis']} reports alarm {r['alarm_code']}: {r['alarm']}"
                     + (" (latched)" if r.get("alarm_latched") else " (a notice)")
                     for r in alarmed)
    latched = [r for r in alarmed if r.get("alarm_latched")]
    if latched:
        code = latched[0]["alarm_code"]
        raise DriveAlarm(what, code=code if isinstance(code, int) else 0)
    raise CliError(what, "the drive keeps working; the notice goes once its cause is gone",
                   EXIT_FAULT)


def render_machine_table(con: Console, name: str, records: list[dict[str, object]]) -> None:
    """Plain columns (no wrapping or ellipsis whatever the terminal width)."""
    head = ("axis", "position", "counts", "enabled", "moving", "in_pos", "f_error", "alarm",
            "link")
    rows: list[tuple[str, ...]] = []
    for r in records:
        link = f"{r['url']} {id_words(r['id'] if isinstance(r['id'], int) else None)}"
        if not r["online"]:
            rows.append((str(r["axis"]), "-", "-", "-", "-", "-", "-", "-",
                         f"{link} OFFLINE: {r.get('error', '')}"))
            continue
        position = r["position"]
        assert isinstance(position, float)
        rows.append((str(r["axis"]), f"{fixed(position, 3)} {r['unit']}", str(r["counts"]),
                     _yes(r["enabled"]), _yes(r["moving"]), _yes(r["in_position"]),
                     _error(r.get("following_error")), str(r["alarm"]) or "-",
                     f"{link} ({r['protocol']})"))
    widths = [max(len(row[i]) for row in (head, *rows)) for i in range(len(head))]
    right = (1, 2, 6)
    lines = [f"machine {name}"]
    for row in (head, *rows):
        cells = [cell.rjust(w) if i in right else cell.ljust(w)
                 for i, (cell, w) in enumerate(zip(row, widths, strict=True))]
        lines.append("  ".join(cells).rstrip())
    con.print("\n".join(lines), markup=False)


def _yes(value: object) -> str:
    return "yes" if value else "no"


def _error(value: object) -> str:
    """The following error in the table: ``-`` where the drive reports none."""
    return f"{fixed(value, 4)}" if isinstance(value, int | float) else "-"


def position(ctx: CliContext) -> None:
    with open_machine_axis(ctx) as axis:
        counts = axis.counts()
        user = axis.to_user(counts)
        record = {"axis": axis.name, "position": user, "unit": axis.unit, "counts": counts}
    emit(ctx, record,
         lambda con: con.print(f"{fixed(user, 4)} {axis.unit} ({counts} counts)", markup=False))


def move(ctx: CliContext, text: str, relative: bool, wait: bool, wait_timeout: float,
         confirm: bool = False) -> None:
    """``move`` on a machine axis; ``--wait``/``--confirm`` checked as on one drive
    (servobus.cli.arrival)."""
    from servobus.cli.arrival import check_arrival, check_ready, read_status, wait_arrival
    from servobus.cli.motion_guard import stop_on_interrupt
    from servobus.cli.move_profile import apply_profile
    from servobus.machine import parse_quantity

    parse_quantity(text, chosen_unit(ctx), axis=chosen_axis(ctx))  # before a link opens
    with open_machine_axis(ctx) as axis:
        number, unit = parse_quantity(text, axis.unit, axis=axis.name)
        user = axis.to_user(number) if unit == "counts" and axis.online else number
        core = axis.axis
        assert core is not None
        who = f"axis {axis.name} (drive {core.drive_id})"
        with stop_on_interrupt(core):
            if wait or confirm:
                check_ready(who, core.drive_id, read_status(core))
            # A move that is refused sends nothing, not even the profile: checked first.
            if not relative:
                axis.check_target(user)
            elif axis.limits is not None:
                axis.check_target(axis.position() + user)
            written = apply_profile(axis)  # the file's speed/accel, where the drive differs
            start = axis.counts() if relative and (wait or confirm) else 0
            if confirm:
                _confirmed_move(axis, core, user, relative, start)
            elif relative:
                axis.move_by(user)
            else:
                axis.move_to(user)
            record: dict[str, object] = {"axis": axis.name,
                                         "move": "relative" if relative else "absolute",
                                         "target": user, "unit": axis.unit}
            if written:
                record["profile_written"] = written
            if wait:
                window = core.position_window()
                st = (wait_arrival(core, wait_timeout, window) if wait_timeout > 0
                      else axis.status())
                counts = axis.counts()
                record.update(in_position=st.in_position, position=axis.to_user(counts),
                              counts=counts)
                if wait_timeout > 0:  # the target was checked (finite) by the move
                    target = start + axis.to_counts(user)
                    check_arrival(who, core.drive_id, st, counts, target, window,
                                  f" ({fixed(axis.to_user(counts), 4)} {axis.unit})")

    def render(con: Console) -> None:
        verb = "moving by" if relative else "moving to"
        done = (f"; done at {fixed(record['position'], 4)} {axis.unit} "
                f"({record['counts']} counts)" if wait else "")
        con.print(f"axis {axis.name} {verb} {user:g} {axis.unit}{done}", markup=False)

    emit(ctx, record, render)


def _confirmed_move(axis: MachineAxis, core: Axis, user: float, relative: bool,
                    start: int) -> None:
    """The machine's limit checks (nothing sent when they fail), then the Axis's confirmed
    move (observed, never re-sent). ``start``: the position in counts a relative move's end
    point counts from."""
    if relative:
        if axis.limits is not None:
            axis.check_target(axis.to_user(start) + user)
        core.move_by(axis.to_counts(user), confirm=True)
    else:
        axis.check_target(user)
        core.move_to(axis.to_counts(user), confirm=True)


def speed(ctx: CliContext, text: str, for_s: float | None) -> None:
    from servobus.cli.hold import hold_speed, speed_words
    from servobus.machine.units import parse_speed

    value = parse_speed(text, chosen_unit(ctx), axis=chosen_axis(ctx))  # before a link opens
    with open_machine_axis(ctx) as axis:
        unit = axis.speed_unit
        held = hold_speed(axis, value, for_s,
                          announce=f"axis {axis.name} turning at {value:g} {unit} while this "
                                   "command runs (Ctrl-C stops it)")
        record: dict[str, object] = {"axis": axis.name, "speed": value, "unit": unit,
                                     "ended": held.why}
        if held.why in ("for", "limit"):
            record["held_s"] = round(held.seconds, 3)
        if held.why == "limit":
            record["stopped_at"] = axis.position()

    def render(con: Console) -> None:
        if held.why == "limit":
            con.print(f"axis {axis.name} turned at {value:g} {unit}; stopped at its soft "
                      f"limit, {fixed(record['stopped_at'], 3)} {axis.unit}", markup=False)
        else:
            con.print(f"axis {axis.name} " + speed_words(f"{value:g} {unit}", held),
                      markup=False)

    emit(ctx, record, render)


def stop(ctx: CliContext) -> None:
    with open_machine_axis(ctx) as axis:
        axis.stop()
    emit(ctx, {"axis": axis.name, "stopped": True},
         lambda con: con.print(f"axis {axis.name} stopping", markup=False))



def ack(ctx: CliContext) -> None:
    """``servobus ack``: acknowledge a possible power loss of one axis (docs/machine.md).

    A one-shot command has no flag from an earlier process to clear: it tells what the
    drive itself shows - a DYN5's power-cleared cell holds the machine's token unless the
    drive was power-cycled or reset since a machine last left it there - then leaves the
    token again and acknowledges. Families without such a cell cannot tell across
    processes; the command says so."""
    from servobus.machine.axis import POWER_TOKEN

    with open_machine_axis(ctx) as axis:
        marker = axis.core.marker_before
        axis.acknowledge()
    if marker is None:
        seen = "unknown: the family keeps no mark of a power cycle across processes"
    elif marker == POWER_TOKEN:
        seen = "no power cycle since a machine last marked the drive"
    else:
        seen = "the drive was power-cycled or reset since a machine last marked it"
    emit(ctx, {"axis": axis.name, "acknowledged": True, "power_cycle": seen},
         lambda con: con.print(f"axis {axis.name}: acknowledged ({seen})", markup=False))
