"""``servobus sim dyn232``: a virtual DYN2 RS485 line on TCP (serial-to-TCP bridge) or a PTY.

stdout gets one line per endpoint, flushed at once, so scripts and tests can read them::

    listening on tcp://127.0.0.1:40123
    pty /dev/pts/7
    tap on tcp://127.0.0.1:40124
    control on tcp://127.0.0.1:40125

Everything else (drive list, warnings, one line per abuse event, statistics) goes to stderr.
An address that cannot be bound ends the command with one ``error: ...`` line, exit code 2.
"""

from __future__ import annotations

import click

from servobus.cli.sim_cmd import add_sim_command
from servobus.cli.sim_control import control_option, start_control
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.protocols.dyn232.codec import FACTORY_ID
from servobus.protocols.dyn232.server import parse_listen_url, run_server
from servobus.sim.fleet import make_drives, parse_ids
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS, log_to_stderr


def _tcp(option: str, value: str | None) -> tuple[str, int] | None:
    if value is None:
        return None
    try:
        return parse_listen_url(value)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint=option) from None


@click.command("dyn232")
@click.option("--listen", metavar="tcp://HOST:PORT", default=None,
              help="serve the line on TCP (pyserial socket://HOST:PORT connects); PORT 0 picks "
                   "a free port; a missing host means 127.0.0.1  [default: tcp://127.0.0.1:0, "
                   "or none with --pty]")
@click.option("--ids", default=None, metavar="1,2,3",
              help=f"drive ids on the line [default: one drive with the factory id {FACTORY_ID}]")
@click.option("--pty", is_flag=True, help="serve the line on a pseudo-terminal; prints its path")
@click.option("--fast", is_flag=True, help="no 38400-baud pacing: answer at once")
@click.option("--state", metavar="FILE", default=None,
              help="keep each drive's EEPROM (parameters, config, id) in this JSON file")
@click.option("--tap", metavar="tcp://HOST:PORT", default=None,
              help="also serve every byte of the line (both directions) for `servobus sniff`")
@click.option("--model", type=click.Choice(sorted(U.MODELS)), default=U.DEFAULT_MODEL,
              show_default=True, help="drive/motor model")
@click.option("--duration", type=click.FloatRange(min=0.0), default=None, metavar="SECONDS",
              help="stop by itself after this many seconds [default: run until Ctrl-C]")
@click.option("--max-clients", type=click.IntRange(min=1), default=DEFAULT_MAX_CLIENTS,
              show_default=True, help="TCP connections (line and tap) served at once; more "
                                      "are closed at once")
@control_option
def sim_dyn2_cmd(listen: str | None, ids: str | None, pty: bool, fast: bool, state: str | None,
                 tap: str | None, model: str, duration: float | None, max_clients: int,
                 control: tuple[str, int] | None) -> None:
    """Virtual DYN2/DC2 drives sharing one RS485 line (DYN232M protocol)."""
    log_to_stderr()
    try:
        drive_ids = parse_ids(ids) if ids is not None else (FACTORY_ID,)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint="--ids") from None
    endpoint = _tcp("--listen", listen)
    if endpoint is None and not pty:
        endpoint = ("127.0.0.1", 0)
    tap_endpoint = _tcp("--tap", tap)
    drives = make_drives(drive_ids, state=state, model=model)
    pacing = "unpaced (--fast)" if fast else "paced at 38400 8N1"
    banner = (f"servobus sim dyn232: {len(drives)} {model} drive(s), ids "
              f"{','.join(str(d.drive_id) for d in drives)}, {pacing}")

    def ready() -> None:
        click.echo(banner, err=True)
        start_control(control, drives)

    server = run_server(drives, listen=endpoint, pty=pty, tap=tap_endpoint, paced=not fast,
                        duration=duration, max_clients=max_clients, ready=ready)
    line = server.line
    click.echo(f"stopped: {line.packets} packet(s), {line.checksum_errors} checksum error(s), "
               f"{line.framing_errors} framing error(s), {server.runner.rx_dropped} byte(s) "
               f"lost to full receive buffers, {server.cap.refused} connection(s) refused, "
               f"{server.dropped_clients} client(s) dropped for not reading", err=True)


def register(group: click.Group) -> None:
    add_sim_command(group, sim_dyn2_cmd, aliases=("dyn2",))  # the name before protocols/
