"""``servobus demo``: a short scripted session that shows what a drive does (a few seconds).

Runs on the built-in virtual machine by default (servobus.machine.builtin: two DMM axes on
one RS-485 line, a YZ-AIM motor on CAN), or on ``--machine FILE`` (the steps act on
``--axis``, else the file's first axis), or on one drive (``--url``/``--port``/``--can``).
Because it moves motors, running it on a real drive needs ``--yes``. Steps: status (one table
of every axis on a machine), parameters, a 10-revolution point-to-point move with live
position (in the axis's unit on a machine), constant speed (a lease the demo renews,
servobus.cli.hold) then stop, a Max Speed change (the same distance back is visibly
slower), the original value restored, on a machine every axis moved together (with the
measured start skew), and a one-line final status per axis.

Live readouts poll status + position every 0.1 s (20 queries/s), below the ~50 queries/s a
real drive is known to drop silently (docs/dyn232.md).

Ctrl-C or SIGTERM stops the motor before the demo exits (servobus.cli.motion_guard).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import click
from rich.markup import escape

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.drive_cmds import render_status, status_record
from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.hold import TTL_S, owner
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import open_drive_machine
from servobus.cli.output import console, emit_json, fixed, id_words
from servobus.cli.params_cmd import params_table
from servobus.errors import DriveAlarm, DriveTimeout

if TYPE_CHECKING:
    from servobus.axis.sync import Axis
    from servobus.axis.types import AxisStatus
    from servobus.machine import Machine, MachineAxis

POLL_S = 0.1
MOVE_REVS = 10
TURN_RPM = 600
TURN_S = 1.0
SPEED_PARAM = "max_speed"  # the profile speed parameter, where the family has one
#: Step 7 on a machine: every axis to this fraction of the way into its soft limits.
TOGETHER_FRACTION = 0.1


class _Script:
    """Collects the steps for --json and prints them as they happen otherwise."""

    def __init__(self, as_json: bool) -> None:
        self.as_json = as_json
        self.steps: list[dict[str, object]] = []
        self.con = console()
        self.t0 = time.monotonic()

    def step(self, title: str, **data: object) -> dict[str, object]:
        record: dict[str, object] = {"step": title, **data}
        self.steps.append(record)
        if not self.as_json:
            self.con.print(f"\n[bold]{len(self.steps)}. {title}[/bold]")
        return record

    def line(self, text: str) -> None:
        if not self.as_json:
            self.con.print(f"   {text}", markup=False)


class _Where:
    """Positions and speeds as the demo prints them: counts, or the machine axis's unit.

    ``mover`` holds the constant speed as a lease the demo renews while it samples
    (servobus.cli.hold): the machine axis, or the drive as a one-axis machine."""

    def __init__(self, axis: Axis, machine_axis: MachineAxis | None,
                 mover: MachineAxis | None = None) -> None:
        self.axis = axis
        self.m = machine_axis
        self.mover = machine_axis if mover is None else mover

    def position(self, counts: int) -> str:
        if self.m is not None:
            return f"{self.m.to_user(counts):9.3f} {self.m.unit} ({counts:>8} counts)"
        return f"{counts:>9} counts  ({counts / self.axis.counts_per_rev:6.2f} rev)"

    def speed(self, rpm: float) -> str:
        if self.m is not None:
            return f"{self.m.core.scale.from_rpm(rpm):7.2f} {self.m.speed_unit} ({rpm:5.0f} rpm)"
        return f"{rpm:>5} rpm"

    def move_to(self, counts: int) -> None:
        if self.m is not None:  # through the machine: its soft limits are checked
            self.m.move_to(self.m.to_user(counts))
        else:
            self.axis.move_to(counts)

    def move_by(self, counts: int) -> None:
        if self.m is not None:
            self.m.move_by(self.m.to_user(counts))
        else:
            self.axis.move_by(counts)

    def turn(self, rpm: int) -> None:
        """Start the constant speed: a lease (inside the soft limits) unless the axis is
        continuous; the demo renews it while it samples (:meth:`renew`)."""
        if self.mover is not None:
            self.mover.turn(self.mover.core.scale.from_rpm(rpm), owner=owner(), ttl=TTL_S)
        else:
            self.axis.turn(rpm)

    def renew(self) -> None:
        """Keep the constant speed alive; a lease that ended (a link failure) is one error,
        never restarted."""
        m = self.mover
        if m is None or m.continuous or self.axis.continuous:
            return  # open-ended: nothing to renew
        if not m.renew(owner(), TTL_S):
            raise CliError(f"the demo's constant speed ended on axis {m.name}", "check the "
                           "link and the drive, then run the demo again", EXIT_FAULT)

    def stop(self) -> None:
        """The lease ends first, so no target update follows the stop."""
        (self.mover if self.mover is not None else self.axis).stop()


def _follow_move(axis: Axis, where: _Where, script: _Script, timeout: float) -> dict[str, object]:
    """Poll until the move is done, printing the live position; returns the trace."""
    t0 = time.monotonic()
    samples: list[list[float]] = []
    while True:
        status = axis.status()
        pos = axis.position()
        t = time.monotonic() - t0
        samples.append([round(t, 3), pos])
        if status.alarm:
            raise DriveAlarm(f"alarm {status.alarm_code} ({status.alarm_text}) during the demo "
                             "move", status.alarm_code, axis.drive_id)
        busy = not status.idle
        state = "moving" if busy else "on position"
        script.line(f"t={t:5.2f} s  position {where.position(pos)}  {state}")
        if not busy:
            return {"seconds": round(t, 3), "final_position": pos, "samples": samples}
        if t > timeout:
            raise DriveTimeout(f"demo move not finished after {timeout} s")
        time.sleep(POLL_S)


def summary(status: AxisStatus) -> str:
    """One line of an AxisStatus: what a person checks at a glance."""
    alarm = (f"ALARM {status.alarm_code}: {status.alarm_text}"
             + (" (latched)" if status.alarm_latched else "")) if status.alarm else "no alarm"
    return (f"{'enabled' if status.enabled else 'disabled'}, "
            f"{'moving' if status.moving else 'still'}, "
            f"{'in position' if status.in_position else 'not in position'}, {alarm}")


def run_demo(axis: Axis, script: _Script, label: str,
             machine_axis: MachineAxis | None = None, mover: MachineAxis | None = None) -> None:
    """Steps 2-6 (parameters, move, constant speed, a slower move back, restore) on one axis;
    step 1 (status) is the caller's. ``mover``: the one-axis machine of a bare drive, whose
    lease holds the constant speed."""
    where = _Where(axis, machine_axis, mover)
    values = axis.read_params()
    script.step("parameters", params=dict(values), axis=label)
    if not script.as_json:
        script.con.print(params_table(dict(values), f"parameters of {label}", script.con.width,
                                      axis.family))

    counts = axis.revs(MOVE_REVS)
    rec = script.step(f"point-to-point move: move_to({counts}) = {MOVE_REVS} rev"
                      + (f" = {machine_axis.to_user(counts):g} {machine_axis.unit}"
                         if machine_axis is not None else ""), counts=counts)
    where.move_to(counts)
    fast = _follow_move(axis, where, script, timeout=10.0)
    rec.update(fast)

    rec = script.step(f"constant speed: turn({TURN_RPM}) for {TURN_S} s, then stop()",
                      rpm=TURN_RPM)
    where.turn(TURN_RPM)
    t0 = time.monotonic()
    speeds: list[list[float]] = []
    positions: list[list[float]] = []
    while (t := time.monotonic() - t0) < TURN_S:
        where.renew()
        speed = axis.speed()
        pos = axis.position()
        speeds.append([round(t, 3), speed])
        positions.append([round(time.monotonic() - t0, 3), pos])
        script.line(f"t={t:5.2f} s  speed {where.speed(speed)}  position "
                    f"{where.position(pos)}")
        time.sleep(POLL_S * 2)
    where.stop()
    t0 = time.monotonic()
    while (speed := axis.speed()) != 0 and time.monotonic() - t0 < 3.0:
        time.sleep(POLL_S)
    held = axis.position()
    script.line(f"stop(): speed {speed} rpm after {time.monotonic() - t0:.2f} s, "
                f"holding at {where.position(held).strip()}")
    rec.update(speeds=speeds, positions=positions, stopped_speed=speed, held_position=held)

    if SPEED_PARAM in values:
        original = values[SPEED_PARAM]
        slow_value = max(axis.param_info(SPEED_PARAM).minimum, original // 2)
        rec = script.step(f"parameter change: {SPEED_PARAM} {original} -> {slow_value}, "
                          f"move_by({-counts}) = {MOVE_REVS} rev back")
        axis.write_param(SPEED_PARAM, slow_value)
        readback = axis.read_param(SPEED_PARAM)
        script.line(f"{SPEED_PARAM} read back: {readback}")
        where.move_by(-counts)
        slow = _follow_move(axis, where, script, timeout=30.0)
        script.line(f"same distance took {slow['seconds']} s instead of {fast['seconds']} s")
        rec.update(readback=readback, **slow)

        rec = script.step(f"restore {SPEED_PARAM} {original}")
        axis.write_param(SPEED_PARAM, original)
        restored = axis.read_param(SPEED_PARAM)
        script.line(f"{SPEED_PARAM} read back: {restored}")
        rec.update(restored=restored)


def _together_targets(machine: Machine) -> dict[str, float]:
    targets: dict[str, float] = {}
    for name, axis in machine.axes.items():
        low, high = axis.limits if axis.limits is not None else (-10.0, 10.0)
        targets[name] = round(low + (high - low) * (0.5 + TOGETHER_FRACTION), 3) \
            if low > 0 or high < 0 else round(high * TOGETHER_FRACTION, 3)
    return targets


def run_machine_demo(machine: Machine, chosen: str, script: _Script) -> None:
    """The demo on a machine: every axis's status, steps 2-6 on ``chosen``, every axis moved
    together, a final line per axis."""
    from servobus.cli.machine_cli import axis_record, render_machine_table

    records = [axis_record(a) for a in machine.axes.values()]
    script.step("status", axes=records)
    if not script.as_json:
        render_machine_table(script.con, machine.name, records)
    m = machine[chosen]
    axis = m.axis
    assert axis is not None
    run_demo(axis, script, f"axis {m.name} ({axis.family.title} over {axis.protocol}, "
                           f"id {axis.drive_id})", m)

    targets = _together_targets(machine)
    rec = script.step("move together: " + ", ".join(
        f"{n} -> {v:g} {machine[n].unit}" for n, v in targets.items()), targets=targets)
    report = machine.move_together(targets)
    t0 = time.monotonic()
    for a in machine.axes.values():
        a.wait_idle(30.0)
    seconds = time.monotonic() - t0
    finals = {n: round(a.position(), 3) for n, a in machine.axes.items()}
    groups = "; ".join("+".join(g) + " by one trigger" for g in report.groups)
    script.line(f"started within {report.skew_s * 1000:.2f} ms of each other"
                f"{' (' + groups + ')' if groups else ' (no shared synchronised start)'}; "
                f"all on position after {seconds:.2f} s")
    for n, v in finals.items():
        script.line(f"{n}: {v:g} {machine[n].unit}")
    rec.update(report.as_dict(), final=finals)

    rec = script.step("final status")
    lines: dict[str, str] = {}
    for n, a in machine.axes.items():
        lines[n] = f"{fixed(a.position(), 3)} {a.unit}, {summary(a.status())}"
        script.line(f"{n}: {lines[n]}")
    rec.update(axes=lines)


@click.command("demo", cls=ServobusCommand)
@click.option("--yes", is_flag=True, help="allow the demo on a real drive (it moves the motor)")
@pass_cli
def demo_cmd(ctx: CliContext, yes: bool) -> None:
    """A short scripted session on the built-in virtual machine: status, parameters, moves."""
    script = _Script(ctx.json)
    if ctx.machine_mode or not ctx.url_given:
        label = _machine_demo(ctx, yes, script)
    else:
        label = _drive_demo(ctx, yes, script)
    elapsed = round(time.monotonic() - script.t0, 2)
    if ctx.json:
        emit_json({"connection": label, "seconds": elapsed, "steps": script.steps})
    else:
        script.con.print(f"\ndone in {elapsed} s")


def _drive_demo(ctx: CliContext, yes: bool, script: _Script) -> str:
    real = not ctx.url.startswith("sim:")
    if real and not yes:
        raise click.UsageError("the demo moves the motor; add --yes to run it on a real drive")
    with open_drive_machine(ctx) as mover, stop_on_interrupt(mover):
        axis = mover.axis
        assert axis is not None  # opened without retry: a failure raised
        label = f"{ctx.url}, id {axis.drive_id}"
        if not ctx.json:
            script.con.print(f"[bold]servobus demo[/bold] on {escape(label)}")
        record = status_record(axis, axis.status())
        script.step("status", **record)
        if not script.as_json:
            render_status(script.con, record, f"status of {label}")
        run_demo(axis, script, f"drive {axis.drive_id}", mover=mover)
        st = axis.status()
        script.step("final status", position=axis.position(), summary=summary(st))
        script.line(f"position {axis.position()} counts, {summary(st)}")
    return label


def _machine_demo(ctx: CliContext, yes: bool, script: _Script) -> str:
    from servobus.cli.machine_cli import (
        note_builtin_machine_once,
        note_origins_skipped,
        spec_names,
    )
    from servobus.machine import open_machine
    from servobus.machine.builtin import builtin_spec
    from servobus.machine.config import load_machine_file

    path = ctx.machine_path
    spec = builtin_spec() if path is None else load_machine_file(path)
    real = [a.name for a in spec.axes if not a.url.startswith("sim:")]
    if real and not yes:
        raise click.UsageError(f"the demo moves the motors ({', '.join(real)} are real drives); "
                               "add --yes to run it")
    source, names = spec_names(ctx)
    chosen = ctx.axis_option or names[0]
    if chosen not in names:
        raise click.UsageError(f"no axis {chosen!r} in {source}; axes: {', '.join(names)}")
    label = f"machine {spec.name} ({source})"
    if not ctx.json:
        script.con.print("[bold]servobus demo[/bold] on " + escape(
            f"{label}: " + ", ".join(f"{a.name} ({a.url} {id_words(a.drive_id)}, {a.unit})"
                                     for a in spec.axes)))
    machine = open_machine(path, origins=False)  # a one-shot command (machine_cli)
    note_origins_skipped(machine)
    try:
        with stop_on_interrupt(machine[chosen]):
            try:
                run_machine_demo(machine, chosen, script)
            except KeyboardInterrupt:
                machine.stop_all()
                raise
    finally:
        machine.close()  # a demo leaves nothing moving
    if path is None:
        note_builtin_machine_once()
    return label


def register(group: click.Group) -> None:
    group.add_command(demo_cmd)
