"""``servobus demo``: a short scripted session that shows what a drive does (a few seconds).

Runs on the embedded virtual drive by default. Because it moves the motor, running it on a
real drive (``--port``/``--can``) needs ``--yes``. Steps: status, parameters, a 10-revolution
point-to-point move with live position, constant speed then stop, a Max Speed change (the
same distance back is visibly slower), the original value restored, final status.

Live readouts poll status + position every 0.1 s (20 queries/s), below the ~50 queries/s a
real drive is known to drop silently (docs/dyn232.md).

Ctrl-C or SIGTERM stops the motor before the demo exits (servobus.cli.motion_guard).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.drive_cmds import render_status, status_record
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import connection_label, console, emit_json, open_axis
from servobus.cli.params_cmd import params_table
from servobus.errors import DriveAlarm, DriveTimeout

if TYPE_CHECKING:
    from servobus.axis.sync import Axis

POLL_S = 0.1
MOVE_REVS = 10
TURN_RPM = 600
TURN_S = 1.0
SPEED_PARAM = "max_speed"  # the profile speed parameter, where the family has one


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
            self.con.print(f"   {text}")


def _follow_move(axis: Axis, script: _Script, timeout: float) -> dict[str, object]:
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
        script.line(f"t={t:5.2f} s  position {pos:>9} counts  "
                    f"({pos / axis.counts_per_rev:6.2f} rev)  {state}")
        if not busy:
            return {"seconds": round(t, 3), "final_position": pos, "samples": samples}
        if t > timeout:
            raise DriveTimeout(f"demo move not finished after {timeout} s")
        time.sleep(POLL_S)


def run_demo(axis: Axis, script: _Script, label: str) -> None:
    record = status_record(axis, axis.status())
    script.step("status", **record)
    if not script.as_json:
        render_status(script.con, record, label)

    values = axis.read_params()
    script.step("parameters", params=dict(values))
    if not script.as_json:
        script.con.print(params_table(dict(values), "parameters", script.con.width, axis.family))

    counts = axis.revs(MOVE_REVS)
    rec = script.step(f"point-to-point move: move_to({counts}) = {MOVE_REVS} rev",
                      counts=counts)
    axis.move_to(counts)
    fast = _follow_move(axis, script, timeout=10.0)
    rec.update(fast)

    rec = script.step(f"constant speed: turn({TURN_RPM}) for {TURN_S} s, then stop()",
                      rpm=TURN_RPM)
    axis.turn(TURN_RPM)
    t0 = time.monotonic()
    speeds: list[list[float]] = []
    while (t := time.monotonic() - t0) < TURN_S:
        speed = axis.speed()
        speeds.append([round(t, 3), speed])
        script.line(f"t={t:5.2f} s  speed {speed:>5} rpm  position {axis.position():>9} counts")
        time.sleep(POLL_S * 2)
    axis.stop()
    t0 = time.monotonic()
    while (speed := axis.speed()) != 0 and time.monotonic() - t0 < 3.0:
        time.sleep(POLL_S)
    held = axis.position()
    script.line(f"stop(): speed {speed} rpm after {time.monotonic() - t0:.2f} s, "
                f"holding at {held} counts")
    rec.update(speeds=speeds, stopped_speed=speed, held_position=held)

    if SPEED_PARAM in values:
        original = values[SPEED_PARAM]
        slow_value = max(axis.param_info(SPEED_PARAM).minimum, original // 2)
        rec = script.step(f"parameter change: {SPEED_PARAM} {original} -> {slow_value}, "
                          f"move_by({-counts}) = {MOVE_REVS} rev back")
        axis.write_param(SPEED_PARAM, slow_value)
        readback = axis.read_param(SPEED_PARAM)
        script.line(f"{SPEED_PARAM} read back: {readback}")
        axis.move_by(-counts)
        slow = _follow_move(axis, script, timeout=30.0)
        script.line(f"same distance took {slow['seconds']} s instead of {fast['seconds']} s")
        rec.update(readback=readback, **slow)

        rec = script.step(f"restore {SPEED_PARAM} {original}")
        axis.write_param(SPEED_PARAM, original)
        restored = axis.read_param(SPEED_PARAM)
        script.line(f"{SPEED_PARAM} read back: {restored}")
        rec.update(restored=restored)

    record = status_record(axis, axis.status())
    script.step("final status", **record)
    if not script.as_json:
        render_status(script.con, record, label)


@click.command("demo", cls=ServobusCommand)
@click.option("--yes", is_flag=True, help="allow the demo on a real drive (it moves the motor)")
@pass_cli
def demo_cmd(ctx: CliContext, yes: bool) -> None:
    """A short scripted session on the embedded virtual drive: status, parameters, moves."""
    real = ctx.url_given and not ctx.url.startswith("sim:")
    if real and not yes:
        raise click.UsageError("the demo moves the motor; add --yes to run it on a real drive")
    label = connection_label(ctx)
    script = _Script(ctx.json)
    if not ctx.json:
        script.con.print(f"[bold]servobus demo[/bold] on {label}"
                         + ("" if ctx.url_given else " (embedded virtual drive)"))
    with open_axis(ctx) as axis, stop_on_interrupt(axis):
        run_demo(axis, script, f"status of {label}")
    elapsed = round(time.monotonic() - script.t0, 2)
    if ctx.json:
        emit_json({"connection": label, "seconds": elapsed, "steps": script.steps})
    else:
        script.con.print(f"\ndone in {elapsed} s")


def register(group: click.Group) -> None:
    group.add_command(demo_cmd)
