"""``servobus gui``: the browser app for every axis of a machine or of one connection.

``--machine FILE`` (or the global ``--machine``/SERVOBUS_MACHINE): every axis of the file,
across links and vendors (docs/machine.md). Otherwise the drive comes from ``gui --url`` or
the global ``--url``/``--port``/``--can``/SERVOBUS_URL, ``--ids`` naming the drives on the
line or bus, ``--id`` one of them; ``--ids`` alone: those virtual drives on one line. With
nothing named: the built-in virtual machine (two DMM axes on RS-485, a YZ-AIM on CAN).

Decision: Ctrl-C and SIGTERM are how a server is meant to end, so they end ``servobus gui``
normally (exit 0, one line on stdout saying every axis was stopped), not with an ``error:``
line and 130 like a command cut short; an axis that did not confirm its stop is an error
(exit 2) naming it. The machine's and the GUI's events (a link lost or back, a possible
power loss, an acknowledgement) go to stderr, one line each (servobus.cli.event_log).
"""

from __future__ import annotations

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.event_log import log_events
from servobus.cli.failures import CliError

SHUTDOWN_NOTE = "every axis was stopped and the GUI server closed"


def parse_ids(text: str) -> tuple[int, ...]:
    """``1,2,3`` -> (1, 2, 3): integers 0..255, no duplicates (the protocol checks its range)."""
    try:
        ids = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise click.BadParameter(f"{text!r}: write drive ids as 1,2,3", param_hint="--ids") \
            from None
    if not ids or any(not 0 <= i <= 255 for i in ids) or len(set(ids)) != len(ids):
        raise click.BadParameter(f"{text!r}: distinct drive ids 0..255, e.g. 1,2,3",
                                 param_hint="--ids")
    return ids


@click.command("gui", cls=ServobusCommand)
@click.option("--url", "gui_url", metavar="URL", default=None,
              help="the drive connection (default: the global --url, else three virtual "
                   "drives)")
@click.option("--machine", "machine", metavar="FILE", default=None,
              help="a machine file: every axis it names (default: the global --machine)")
@click.option("--id", "one_id", type=click.IntRange(0, 255), default=None,
              help="one drive id on the connection")
@click.option("--ids", "ids_text", metavar="1,2,3", default=None,
              help="several drive ids on the connection (one axis each)")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="address to listen on; other than loopback needs a token")
@click.option("--port", type=click.IntRange(0, 65535), default=8080, show_default=True,
              help="TCP port (0: any free port)")
@click.option("--no-browser", is_flag=True, help="do not open a browser")
@click.option("--token", default=None,
              help="required in the page URL; generated when listening beyond loopback")
@pass_cli
def gui(ctx: CliContext, gui_url: str | None, machine: str | None, one_id: int | None,
        ids_text: str | None, host: str, port: int, no_browser: bool,
        token: str | None) -> None:
    """Tune, command and watch drives in a browser (live scope, step tests, parameters).

    Binds 127.0.0.1 by default. Ctrl-C or SIGTERM stops every axis, then the server
    (exit 0; exit 2 with an error line if an axis did not confirm its stop).
    """
    from servobus.gui.server import ServeOptions, serve

    if one_id is not None and ids_text is not None:
        raise click.UsageError("give --id or --ids, not both")
    if ids_text is not None:
        ids: tuple[int, ...] | None = parse_ids(ids_text)
    elif (single := one_id if one_id is not None else ctx.drive_id) is not None:
        ids = (single,)
    else:
        ids = None
    url = gui_url or ctx.named_url
    machine = machine or (ctx.machine_path if gui_url is None else None)
    if machine is not None and (gui_url or ctx.url_option or ctx.port or ctx.can or ids):
        raise click.UsageError("give --machine FILE or a drive (--url/--id/--ids), not both")
    if machine is not None:
        url = None
    options = ServeOptions(url=url, ids=ids, host=host, port=port, token=token,
                           open_browser=not no_browser, machine=machine)
    log_events("servobus.machine", "servobus.gui")  # links lost and back, power losses
    outcome = serve(options, lambda line: click.echo(line))
    failed = {i: e for i, e in (outcome.halted or {}).items() if e is not None}
    if failed:
        what = "; ".join(f"axis {i}: {type(e).__name__}: {e}" for i, e in failed.items())
        raise CliError(f"the GUI server closed but not every axis confirmed its stop ({what})",
                       "check those drives now: they may still be moving")
    if outcome.signal is not None:
        click.echo(f"servobus gui: {outcome.signal}: {SHUTDOWN_NOTE}")


def register(group: click.Group) -> None:
    group.add_command(gui)
