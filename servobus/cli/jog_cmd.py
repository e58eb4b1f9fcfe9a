"""``servobus jog``: move an axis with the arrow keys of a terminal, as DMMDRV's jog buttons.

The motion is a lease held by this command (docs/safety.md; as ``speed``): the axis turns
at ``--speed`` (the axis's unit per second on a machine axis, rpm on a drive) while a key
arrives, through the machine axis's ``jog`` (a target a bounded lead ahead of the motor,
never past a soft limit), renewed every :data:`~servobus.cli.hold.RENEW_S` by the command.

Decisions (terminals send no key-up, servobus.cli.jog_keys):

* Right/Up jog towards increasing position, Left/Down towards decreasing; the other
  direction's key reverses at once.
* The motion stops ``--release`` seconds after the last arrow key (default 0.7 s: X11's
  repeat delay is 0.66 s, so a held key's first repeat arrives in time), on any other key,
  or on Ctrl-C/SIGTERM (exit 130); q or Ctrl-D stop it and end the command (exit 0).
* When the command dies, the renewals stop and the drive comes to rest within the lease's
  bound; when it hangs, the lease's ttl ends the motion.
* At a soft limit the jog refuses to head further out (one line) and waits for the other
  direction's key.
* :class:`Jogger` takes its keys and its clock from outside: a test scripts both.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import click

from servobus.cli import machine_cli
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import EXIT_FAULT, CliError
from servobus.cli.hold import RENEW_S, TTL_S
from servobus.cli.jog_keys import MINUS, PLUS, QUIT, KeySource, TerminalKeys
from servobus.cli.motion_guard import stop_on_interrupt
from servobus.cli.open_axis import open_drive_machine
from servobus.cli.output import emit, fixed, note
from servobus.cli.param_types import Seconds
from servobus.errors import LimitError

if TYPE_CHECKING:
    from servobus.machine import MachineAxis
    from servobus.machine.lease import Lease

#: Default --release, seconds (module docstring).
RELEASE_S = 0.7
#: A wait the key source timed out on counts as done this close to its end (a clock that
#: adds the wait back may fall an ulp short and would then wait 0 s for ever).
CLOCK_EPS_S = 1e-6
#: Default speed on a single drive, rpm (one revolution a second: slow on any mechanics).
DRIVE_RPM = 60.0


class Jogged(Protocol):
    """What the jogger calls: a MachineAxis (whose jog/renew/stop hold the lease)."""

    @property
    def lease(self) -> Lease | None: ...
    def jog(self, speed: float | None = None, *, owner: str = ..., ttl: float = ...) -> None: ...
    def renew(self, owner: str, ttl: float = ...) -> bool: ...
    def stop(self) -> None: ...


@dataclass
class Jogger:
    """Keys in, leased motion out (module docstring); :meth:`run` until q or Ctrl-D."""

    axis: Jogged
    speed: float  # > 0, the axis's unit per second
    release: float  # seconds
    keys: KeySource
    clock: Callable[[], float] = time.monotonic
    say: Callable[[str], None] = note
    speed_text: str = ""  # how --speed reads to the user ("50 mm/s")
    owner: str = field(default_factory=lambda: f"servobus jog (pid {os.getpid()})")
    heading: int = 0  # +1 / -1 while a jog runs, 0 at rest
    last_key: float = 0.0
    starts: int = 0  # jogs started (a reversal starts one)
    _at_limit: bool = False

    def run(self) -> str:
        """Read keys until q/Ctrl-D ("quit"); a motion that runs is stopped first."""
        while True:
            wait = None
            if self.heading:
                wait = min(RENEW_S, max(0.0, self.last_key + self.release - self.clock()))
            key = self.keys.read(wait)
            now = self.clock()
            if key in (PLUS, MINUS):
                self.last_key = now
                self._go(1 if key == PLUS else -1)
            elif key == QUIT:
                self._halt("quit")
                return "quit"
            elif key is not None:
                self._halt("another key")
            elif self.heading and now - self.last_key >= self.release - CLOCK_EPS_S:
                self._halt(f"released ({self.release:g} s after the last key)")
            elif self.heading:
                self._renew()

    def _go(self, heading: int) -> None:
        if heading == self.heading:
            self._renew()
            return
        try:
            self.axis.jog(heading * self.speed, owner=self.owner, ttl=TTL_S)
        except LimitError as exc:
            self.heading = 0
            self.say(f"{exc}")
            return
        self.heading, self._at_limit = heading, False
        self.starts += 1
        self.say(f"jogging {'+' if heading > 0 else '-'} at {self.speed_text}")

    def _renew(self) -> None:
        if not self.axis.renew(self.owner, TTL_S):
            lease = self.axis.lease
            self.heading = 0
            why = lease.ended if lease is not None and lease.ended else "ended"
            raise CliError(f"the jog ended ({why}); the drive rests at its last target",
                           "check the link and the drive, then jog again", EXIT_FAULT)
        lease = self.axis.lease
        if lease is not None and lease.at_limit and not self._at_limit:
            self._at_limit = True
            self.say("at the soft limit: the jog goes no further this way")

    def _halt(self, why: str) -> None:
        if self.heading:
            self.axis.stop()
            self.heading = 0
            self.say(f"stopped: {why}")


@contextmanager
def _opened(ctx: CliContext, speed: float | None) -> Iterator[tuple[MachineAxis, float, str]]:
    """The axis to jog, the speed in its unit per second, and how to say the speed."""
    if ctx.machine_mode:
        with machine_cli.open_machine_axis(ctx) as axis:
            value = speed if speed is not None else axis.core.default_speed
            if value is None:
                raise click.UsageError(f"the machine file gives axis {axis.name} no speed: "
                                       f"give --speed in {axis.speed_unit}")
            yield axis, value, f"{value:g} {axis.speed_unit}"
        return
    with open_drive_machine(ctx) as axis:
        rpm = DRIVE_RPM if speed is None else speed
        yield axis, axis.core.scale.from_rpm(rpm), f"{rpm:g} rpm"


def terminal_keys() -> TerminalKeys:
    """The keys of the terminal on standard input (UsageError when it is not one)."""
    if not sys.stdin.isatty():
        raise click.UsageError("jog reads the arrow keys of a terminal, and standard input "
                               "is not one")
    return TerminalKeys(sys.stdin.fileno())


@click.command("jog", cls=ServobusCommand)
@click.option("--speed", type=float, default=None, metavar="V",
              help="the jog speed: the axis's unit per second on a machine axis [default: the "
                   "file's speed], rpm on a drive [default: 60]")
@click.option("--release", type=Seconds(), default=RELEASE_S, show_default=True,
              help="seconds after the last arrow key that the motion stops (terminals send no "
                   "key-up: a held key's auto-repeat keeps it going)")
@pass_cli
def jog_cmd(ctx: CliContext, speed: float | None, release: float) -> None:
    """Jog with the arrow keys: Right/Up +, Left/Down -, while the key is held.

    The motion stops RELEASE seconds after the last key, on any other key, or on Ctrl-C;
    q ends the command. It is a lease held by the command (docs/safety.md): if the
    command dies, the drive comes to rest by itself within a bounded distance."""
    if speed is not None and (not speed > 0 or speed == float("inf")):
        raise click.BadParameter(f"{speed:g}: give a speed above 0", param_hint="--speed")
    keys = terminal_keys()
    with _opened(ctx, speed) as (axis, value, text), stop_on_interrupt(axis), keys:
        jogger = Jogger(axis, value, release, keys, speed_text=text)
        note(f"jog {axis.name if ctx.machine_mode else 'the drive'} at {text}: hold Right/Up "
             "or Left/Down; any other key stops, q quits")
        ended = jogger.run()
        position, unit = axis.position(), axis.unit
    record = {"axis" if ctx.machine_mode else "drive_id":
              axis.name if ctx.machine_mode else axis.drive_id,
              "jogs": jogger.starts, "ended": ended, "position": position, "unit": unit}
    emit(ctx, record, lambda con: con.print(f"jog ended at {fixed(position, 4)} {unit}"
                                            if unit != "counts" else
                                            f"jog ended at {int(position)} counts",
                                            markup=False))


def register(group: click.Group) -> None:
    group.add_command(jog_cmd)
