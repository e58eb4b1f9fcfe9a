"""``servobus hal``: the LinuxCNC userspace HAL component (docs/linuxcnc.md).

Exit: 130 after SIGTERM/SIGINT/SIGHUP (every position axis stopped first), 2 for a machine file
mistake or a missing ``hal`` module.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.event_log import log_events
from servobus.cli.failures import CliError, Interrupted

EXISTING = click.Path(dir_okay=False, exists=True, path_type=Path)


@click.command("hal", cls=ServobusCommand)
@click.option("--name", default="servobus", show_default=True,
              help="the component's name: its pins are NAME.<axis>.<pin>")
@click.option("--machine", "machine_path", type=EXISTING, default=None,
              help="the machine file (TOML; docs/machine.md) [default: the global --machine "
                   "or SERVOBUS_MACHINE]")
@click.option("--watchdog", "watchdog_s", type=click.FloatRange(0.01, 60), default=0.2,
              show_default=True, metavar="SECONDS",
              help="without a toggle of NAME.watchdog for this long, every position axis stops")
@pass_cli
def hal(ctx: CliContext, name: str, machine_path: Path | None, watchdog_s: float) -> None:
    """A LinuxCNC userspace HAL component serving a machine file's axes.

    Load it with `loadusr -Wn servobus servobus hal --machine cell.toml`. Pins per axis:
    position-fb, velocity-fb, current, following-error, enabled, moving, in-position,
    online, fault, alarm-code (out); enable, fault-reset, position-cmd (in); and
    NAME.fault, NAME.watchdog. docs/linuxcnc.md.
    """
    from servobus.errors import NotSupported
    from servobus.hal.component import serve
    from servobus.hal.module import import_hal
    from servobus.machine.config import load_machine_file

    if machine_path is None and ctx.machine_path is not None:
        machine_path = Path(ctx.machine_path)
    if machine_path is None or not machine_path.is_file():
        raise click.UsageError("servobus hal needs --machine FILE (or SERVOBUS_MACHINE)")
    load_machine_file(machine_path)  # a mistake is one line, LinuxCNC or not
    try:
        hal_module = import_hal()
    except NotSupported as exc:
        raise CliError(str(exc), "docs/linuxcnc.md says how the hal module is found") from None
    log_events("servobus.hal", "servobus.machine")
    caught = asyncio.run(serve(hal_module, machine_path, name, watchdog_s))
    raise Interrupted("Ctrl-C" if caught == "SIGINT" else caught,
                      "every position axis was stopped and the component exited")


def register(group: click.Group) -> None:
    group.add_command(hal)
