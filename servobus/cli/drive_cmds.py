"""Drive commands: ``status``, ``position``, ``speed RPM``, ``move [--relative] TARGET``, ``stop``,
``reset``.

Units are the Axis's, the same on every drive: ``move`` takes encoder counts of the drive
family (``move 16384``), revolutions (``2.5rev``), degrees (``90deg``) or the drive's raw
command units (``120cmd``, where the protocol has them); ``position`` prints counts and
revolutions. Negative numbers are arguments: ``servobus move --relative -120``.
Ctrl-C or SIGTERM during ``move --wait`` stops the motor first (servobus.cli.motion_guard).
``move --wait`` and ``--confirm`` exit 1 when the drive is in alarm or disabled (nothing is
sent) and ``--wait`` when the move ends off its target (servobus.cli.arrival).

``status`` exits 1 when the drive reports an alarm (README "Errors and exit codes"), after
printing the status; ``reset`` clears a latched alarm the family's own way (Axis.reset():
the DMM reset selector, which the drive takes as a power cycle; DYN5 Reset 0x21; YZ-AIM
output_enable 0 then 1) and exits 1 when the alarm is still there afterwards.

Note: without a drive URL each invocation starts its own built-in virtual drive, so state
(position, motion) does not carry over from one command to the next.
"""

from __future__ import annotations

import contextlib
import math
import re
import time
from typing import TYPE_CHECKING, TypeAlias

import click
from rich.console import Console

from servobus.axis.capabilities import Capability
from servobus.axis.units import from_counts, to_counts
from servobus.cli import machine_cli
from servobus.cli.arrival import check_arrival, check_ready, read_status, wait_arrival
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.hold import hold_speed, speed_words
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import connection_label, open_axis, open_drive_machine
from servobus.cli.output import emit, fixed, following_words, kv_text
from servobus.cli.param_types import Seconds
from servobus.errors import ArgumentRangeError, DriveAlarm, DriveTimeout, NotSupported

if TYPE_CHECKING:
    from servobus.axis.sync import Axis
    from servobus.axis.types import AxisStatus

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


def drive_units(ctx: CliContext) -> str:
    """The TARGET forms the named drive takes, from its family's capabilities (nothing is
    opened): raw command units (``120cmd``) only where the family has them."""
    from servobus.axis import registry
    from servobus.axis.url import parse_url
    from servobus.families import family

    forms = "counts (16384), revolutions (2.5rev), degrees (90deg)"
    protocol = registry.protocol_of(parse_url(ctx.url))
    spec = registry.specs().get(protocol) if protocol else None
    if spec is not None and Capability.COMMAND_UNITS not in family(spec.family).capabilities:
        return forms.replace(", degrees", " or degrees")
    return f"{forms} or command units (120cmd)"


def check_drive_target(number: float, unit: str) -> None:
    """A TARGET for a single drive (no machine): whole counts, no mm (nothing is opened)."""
    if unit in ("", "counts", "cmd") and not number.is_integer():
        raise click.BadParameter(f"{number:g}: {unit or 'counts'} are whole numbers",
                                 param_hint="TARGET")
    if unit == "mm":
        raise click.BadParameter("mm needs a machine file that gives the axis's mechanics "
                                 "(--machine FILE, docs/machine.md)", param_hint="TARGET")


def typed(number: float, unit: str) -> str:
    """A TARGET as the user wrote it (``16384``, ``2.5rev``, ``-90deg``)."""
    text = str(int(number)) if number.is_integer() else repr(number)
    return text if unit == "counts" else f"{text}{unit}"


def in_unit(axis: Axis, counts: int, unit: str) -> str:
    """Counts in a TARGET unit, rounded towards zero (a bound stays reachable)."""
    if unit == "counts":
        return str(counts)
    value = math.trunc(from_counts(counts, unit, axis.counts_per_rev) * 1000) / 1000
    return f"{value:.3f}".rstrip("0").rstrip(".")


def check_reach(axis: Axis, counts: int, relative: bool, number: float, unit: str) -> None:
    """ArgumentRangeError naming TARGET as typed and the drive's range in its unit."""
    unit = unit or "counts"  # a bare number on a single drive is counts
    limits = axis.move_range(relative=relative)
    if limits is None or limits[0] <= counts <= limits[1]:
        return
    low, high = (in_unit(axis, bound, unit) for bound in limits)
    what = "move --relative" if relative else "move"
    raise ArgumentRangeError(
        f"{what} {typed(number, unit)}: outside the {low}..{high} "
        f"{'counts' if unit == 'counts' else unit} this drive reaches "
        f"({axis.family.title} over {axis.protocol})")


def status_record(axis: Axis, status: AxisStatus) -> dict[str, object]:
    """--json of ``status``: the AxisStatus at top level, position, the vendor's extras."""
    record: dict[str, object] = {"drive_id": axis.drive_id, "protocol": axis.protocol,
                                 **status.as_dict(), "position": axis.position(),
                                 "following_error": axis.following_error()}
    if status.vendor is not None:
        record["vendor_status"] = status.vendor.as_dict()
    if axis.supports(Capability.CONFIG):
        record["config"] = axis.extra.config().as_dict()
    return record


#: Seconds between the status reads that wait for a reset to take.
RESET_POLL_S = 0.05
#: Titles of the nested blocks of ``status``.
BLOCKS = {"config": "config", "vendor_status": "drive's own status bits"}


def alarm_words(code: object, text: object, latched: object) -> str:
    """``none``, or ``2 over current (latched)``: the alarm the same way on every family."""
    if not code:
        return "none"
    return f"{code} {text}" + (" (latched)" if latched else " (notice, not latched)")


def render_status(con: Console, record: dict[str, object], title: str) -> None:
    top: dict[str, object] = {}
    for key, value in record.items():
        if key in (*BLOCKS, "drive_id", "protocol", "alarm_code", "alarm_latched",
                   "alarm_before"):
            continue
        top[key] = (alarm_words(record["alarm_code"], value, record["alarm_latched"])
                    if key == "alarm" else following_words(value, "counts")
                    if key == "following_error" else value)
    con.print(kv_text(title, top), markup=False)
    for key, block_title in BLOCKS.items():
        block = record.get(key)
        if isinstance(block, dict):
            con.print(kv_text(block_title, block), markup=False)


def alarm_error(axis: Axis, status: AxisStatus) -> DriveAlarm | CliError:
    """The exit-1 error of a drive in alarm: a latched one is a DriveAlarm (whose advice
    names `servobus reset`); a notice (DMM checksum, YZ-AIM battery) needs no reset."""
    what = f"drive {axis.drive_id} reports alarm {status.alarm_code}: {status.alarm_text}"
    if status.alarm_latched:
        return DriveAlarm(f"{what} (latched)", code=status.alarm_code, drive_id=axis.drive_id)
    return CliError(f"{what} (a notice, not latched)",
                    "the drive keeps working; the notice goes once its cause is gone",
                    EXIT_FAULT)


@click.command("status", cls=ServobusCommand)
@pass_cli
def status_cmd(ctx: CliContext) -> None:
    """Decoded drive status (and the drive's configuration where it has one).

    Exits 1 when the drive reports an alarm (`servobus reset` clears a latched one)."""
    if ctx.machine_mode:  # one table of every axis, or the one --axis names
        machine_cli.status(ctx)
        return
    with open_axis(ctx) as axis:
        status = read_status(axis)
        record = status_record(axis, status)
        label = connection_label(ctx, axis)
    emit(ctx, record, lambda con: render_status(con, record, f"status of {label}"))
    if status.alarm:
        raise alarm_error(axis, status)


@click.command("reset", cls=ServobusCommand)
@click.option("--wait-timeout", type=Seconds(), default=15.0, show_default=True,
              help="seconds to wait for the drive to answer again after the reset")
@pass_cli
def reset_cmd(ctx: CliContext, wait_timeout: float) -> None:
    """Clear a latched alarm the drive family's own way, then show the status.

    DMM DYN2/DYN4: the reset selector (the drive takes it as a power cycle); DMM DYN5: Reset
    (0x21 = 0xABCD, the adapter restarts); YZ-AIM, which has no reset command: output enable
0 then 1 (docs/axis.md). Remove the
    cause first: an alarm whose cause remains trips again. Exits 1 if the alarm is still
    there."""
    with open_axis(ctx) as axis:
        axis.require(Capability.RESET)
        before = read_status(axis)
        axis.reset()
        after = _status_after_reset(axis, wait_timeout)
        record = {"alarm_before": before.alarm_code, **status_record(axis, after)}
        label = connection_label(ctx, axis)

    def render(con: Console) -> None:
        con.print(f"reset sent; alarm before: "
                  f"{alarm_words(before.alarm_code, before.alarm_text, before.alarm_latched)}",
                  markup=False)
        render_status(con, record, f"status of {label}")

    emit(ctx, record, render)
    if after.alarm:
        raise alarm_error(axis, after)


def _status_after_reset(axis: Axis, wait_timeout: float) -> AxisStatus:
    """The status once the reset took: the first one without a latched alarm, else the last
    one read when ``wait_timeout`` ends (a drive restarting after its reset may not answer
    for a while, or answer from before it; the reset command itself has no reply)."""
    deadline = time.monotonic() + wait_timeout
    last: AxisStatus | None = None
    while True:
        with contextlib.suppress(DriveTimeout):
            last = read_status(axis)
        if last is not None and not last.alarm_latched:
            return last
        if time.monotonic() >= deadline:
            if last is None:
                raise DriveTimeout(f"drive {axis.drive_id} did not answer within "
                                   f"{wait_timeout:g} s after the reset")
            return last
        time.sleep(RESET_POLL_S)


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
         lambda con: con.print(f"{pos} counts ({fixed(pos / per_rev, 4)} rev)"))


FOR_HELP = ("hold the speed this many seconds, then stop (default: until Ctrl-C or SIGTERM; "
            "on a continuous axis: return at once, the speed stays on)")


@click.command("speed", cls=ServobusCommand)
@click.option("--for", "for_s", type=Seconds(), default=None, metavar="SECONDS", help=FOR_HELP)
@click.argument("speed_text", metavar="SPEED")
@pass_cli
def speed_cmd(ctx: CliContext, for_s: float | None, speed_text: str) -> None:
    """Turn at constant SPEED (whole rpm) while this command runs, then stop (positive = towards
    increasing position; 0 ramps down).

    The command holds the motion (a lease it renews, docs/safety.md): Ctrl-C, SIGTERM or
    --for SECONDS stops it, and if the process dies the drive comes to rest by itself within
    a bounded distance. On a continuous axis (?continuous=1 on the URL, continuous = true in
    a machine file) the speed is open-ended: the command returns at once and `servobus stop`
    stops it.

    On a machine axis (--machine/--axis) the speed is in its unit per second (mm/s, deg/s)."""
    if ctx.machine_mode:
        machine_cli.speed(ctx, speed_text, for_s)
        return
    rpm = drive_rpm(speed_text)
    with open_drive_machine(ctx) as axis:
        core = axis.axis
        assert core is not None  # opened without retry: a failure raised
        if not (axis.continuous or core.continuous):
            check_lease_rpm(core, rpm)
        held = hold_speed(axis, axis.core.scale.from_rpm(rpm), for_s,
                          announce=f"turning at {rpm} rpm while this command runs "
                                   "(Ctrl-C stops it)")
    record: dict[str, object] = {"speed_command": rpm, "ended": held.why}
    if held.why in ("for", "limit"):
        record["held_s"] = round(held.seconds, 3)
    emit(ctx, record, lambda con: con.print(speed_words(f"{rpm} rpm", held)))


def drive_rpm(text: str) -> int:
    """A drive's SPEED: whole rpm (``600``, ``-600rpm``); a speed in a user unit needs the
    mechanics of a machine axis."""
    match = re.fullmatch(r"([-+]?\d+(?:\.\d*)?|[-+]?\.\d+)\s*(rpm)?", text.strip().lower())
    if match is None:
        raise click.BadParameter(f"{text!r}: a drive's speed is whole rpm, e.g. 600 (speeds in "
                                 "mm/s or deg/s need a machine axis: --machine FILE --axis "
                                 "NAME)", param_hint="SPEED")
    rpm = float(match.group(1))
    if not rpm.is_integer():
        raise click.BadParameter(f"{rpm:g} is not a whole number of rpm", param_hint="SPEED")
    return int(rpm)


def check_lease_rpm(axis: Axis, rpm: int) -> None:
    """A held speed runs the drive's own profile: above its top speed it is refused in rpm
    (the EEPROM's max_speed is never raised per motion), before anything is sent."""
    top = math.floor(axis.stream_profile().max_rpm)
    if abs(rpm) > top:
        raise ArgumentRangeError(f"speed {rpm} rpm is outside the -{top}..{top} rpm the "
                                 f"drive's profile runs ({axis.family.title} over "
                                 f"{axis.protocol}, its max_speed)")


@click.command("move", cls=ServobusCommand)
@click.option("--relative", is_flag=True, help="move by TARGET instead of to TARGET")
@click.option("--wait", is_flag=True, help="wait until the move is finished and on position")
@click.option("--wait-timeout", type=Seconds(allow_zero=True), default=30.0, show_default=True,
              help="seconds --wait waits before DriveTimeout")
@click.option("--confirm", is_flag=True,
              help="check that the drive took the move (status/position); never re-sent")
@click.option("--together", is_flag=True,
              help="absolute moves of several machine axes started together: NAME=TARGET ...")
@click.argument("targets", nargs=-1, required=True, metavar="TARGET")
@pass_cli
def move_cmd(ctx: CliContext, relative: bool, wait: bool, wait_timeout: float, confirm: bool,
             together: bool, targets: tuple[str, ...]) -> None:
    """Point-to-point move to/by TARGET: counts (16384), 2.5rev, 90deg or 120cmd.

    On a machine axis (--machine/--axis) a bare number is in the axis's unit (12.5 = 12.5 mm),
    checked against its soft limits before anything is sent, and the machine file's speed
    and accel set the drive's move profile (written only where the drive differs).
    With --together: `move --together x=10 y=20` starts several axes together and says
    what the start skew can be."""
    if together:
        from servobus.cli.together_cmd import move_together

        move_together(ctx, targets, relative=relative, wait=wait, wait_timeout=wait_timeout,
                      confirm=confirm)
        return
    if len(targets) != 1:
        raise click.UsageError("move takes one TARGET (several NAME=TARGET with --together)")
    if ctx.machine_mode:  # in the axis's unit: its own parser names only what it accepts
        machine_cli.move(ctx, targets[0], relative, wait, wait_timeout, confirm)
        return
    try:
        number, unit = Target().convert(targets[0], None, None)
    except click.BadParameter:
        raise click.BadParameter(f"{targets[0]!r}: write {drive_units(ctx)}",
                                 param_hint="'TARGET'") from None
    check_drive_target(number, unit)
    with open_axis(ctx) as axis, stop_on_interrupt(axis):
        who = f"drive {axis.drive_id}"
        if wait or confirm:  # a drive in alarm or disabled would not move (cli.arrival)
            check_ready(who, axis.drive_id, read_status(axis))
        start = axis.position() if wait and relative else 0  # where "by" counts from
        if unit == "cmd":
            if not axis.supports(Capability.COMMAND_UNITS):
                raise NotSupported(f"{axis.family.title} over {axis.protocol} has no raw "
                                   "command units; give counts, rev or deg", axis.family.name)
            (axis.extra.move_by_command if relative else axis.extra.move_to_command)(int(number))
            record: dict[str, object] = {"command_units": int(number)}
        else:
            counts = to_counts(number, unit or "counts", axis.counts_per_rev)
            check_reach(axis, counts, relative, number, unit)
            (axis.move_by if relative else axis.move_to)(counts, confirm=confirm)
            record = {"counts": counts}
        record["move"] = "relative" if relative else "absolute"
        if wait:
            window = axis.position_window()
            status = (wait_arrival(axis, wait_timeout, window) if wait_timeout > 0
                      else axis.status())
            here = axis.position()
            record.update(in_position=status.in_position, position=here, window=window)
            if unit != "cmd":
                record["target"] = start + counts
            if wait_timeout > 0:
                check_arrival(who, axis.drive_id, status, here,
                              None if unit == "cmd" else start + counts, window)

    def render(con: Console) -> None:
        verb = "moving by" if relative else "moving to"
        what = f"{int(number)} command units" if unit == "cmd" else f"{record['counts']} counts"
        con.print(f"{verb} {what}" + (f"; {done_text(record)}" if wait else ""))

    emit(ctx, record, render)


def done_text(record: dict[str, object]) -> str:
    """Where a waited move ended, and why that need not be the target to the count: the
    drive reports "in position" within its window (DMM OnRange, YZ-AIM +-10 counts)."""
    position, window, target = record["position"], record["window"], record.get("target")
    if not (isinstance(position, int) and isinstance(target, int) and isinstance(window, int)):
        return f"done at {position} counts"
    off = position - target
    if off == 0:
        return f"done at {position} counts, on the target"
    place = "inside" if abs(off) <= window else "outside"
    return (f"done at {position} counts, {off:+d} from the target: {place} the drive's "
            f"in-position window of +-{window} counts")


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


@click.command("ack", cls=ServobusCommand)
@pass_cli
def ack_cmd(ctx: CliContext) -> None:
    """Acknowledge a possible power loss of a machine axis (--axis; docs/machine.md)."""
    if not ctx.machine_mode:
        raise click.UsageError("ack acts on a machine axis: give --machine FILE --axis NAME "
                               "(or --axis NAME on the built-in machine)")
    machine_cli.ack(ctx)


def register(group: click.Group) -> None:
    for command in (status_cmd, position_cmd, speed_cmd, move_cmd, stop_cmd, reset_cmd,
                    ack_cmd):
        group.add_command(command)
