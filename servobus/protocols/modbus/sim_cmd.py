"""``servobus sim modbus``: virtual YZ-AIM motors on one Modbus RTU line, on TCP (a
serial-to-TCP bridge) or a PTY, paced at the baud rate (19200 8N1 by default).

stdout gets one line per endpoint, flushed at once, so scripts and tests can read them::

    listening on tcp://127.0.0.1:40123
    pty /dev/pts/7
    tap on tcp://127.0.0.1:40124

Everything else (motor list, warnings, statistics) goes to stderr. Connect with
``servobus --url modbus+socket://127.0.0.1:40123 --id 1 status`` or pymodbus
(docs/modbus.md).
"""

from __future__ import annotations

import click

from servobus.cli.sim_cmd import add_sim_command
from servobus.errors import ArgumentRangeError
from servobus.families import yzaim as Y
from servobus.protocols.modbus.inprocess import FACTORY_ADDRESS, make_motors, parse_addresses
from servobus.protocols.modbus.server import run_server
from servobus.protocols.modbus.timing import DEFAULT_BAUD
from servobus.sim.line_server import parse_listen_url
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS, log_to_stderr


def _tcp(option: str, value: str | None) -> tuple[str, int] | None:
    if value is None:
        return None
    try:
        return parse_listen_url(value)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint=option) from None


@click.command("modbus")
@click.option("--listen", metavar="tcp://HOST:PORT", default=None,
              help="serve the line on TCP (modbus+socket://HOST:PORT connects); PORT 0 picks "
                   "a free port; a missing host means 127.0.0.1  [default: tcp://127.0.0.1:0, "
                   "or none with --pty]")
@click.option("--ids", default=str(FACTORY_ADDRESS), show_default=True, metavar="1,2,3",
              help="device addresses on the line (1..254)")
@click.option("--pty", is_flag=True, help="serve the line on a pseudo-terminal; prints its path")
@click.option("--fast", is_flag=True, help="no baud-rate pacing: answer at once")
@click.option("--baud", type=click.IntRange(min=300), default=DEFAULT_BAUD, show_default=True,
              help="the line's baud rate (8N1): pacing and the t3.5 frame gap")
@click.option("--state", metavar="FILE", default=None,
              help="keep each motor's EEPROM (saved registers, position) in this JSON file")
@click.option("--tap", metavar="tcp://HOST:PORT", default=None,
              help="also serve every frame of the line (both directions) for `servobus sniff`")
@click.option("--model", type=click.Choice(sorted(Y.MODEL_BY_NAME)), default=Y.DEFAULT_MODEL,
              show_default=True, help="YZ-AIM motor model")
@click.option("--duration", type=click.FloatRange(min=0.0), default=None, metavar="SECONDS",
              help="stop by itself after this many seconds [default: run until Ctrl-C]")
@click.option("--max-clients", type=click.IntRange(min=1), default=DEFAULT_MAX_CLIENTS,
              show_default=True, help="TCP connections (line and tap) served at once; more "
                                      "are closed at once")
def sim_modbus_cmd(listen: str | None, ids: str, pty: bool, fast: bool, baud: int,
                   state: str | None, tap: str | None, model: str, duration: float | None,
                   max_clients: int) -> None:
    """Virtual YZ-AIM motors sharing one Modbus RTU line (RS-485 multi-drop)."""
    log_to_stderr()
    try:
        addresses = parse_addresses(ids)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint="--ids") from None
    endpoint = _tcp("--listen", listen)
    if endpoint is None and not pty:
        endpoint = ("127.0.0.1", 0)
    tap_endpoint = _tcp("--tap", tap)
    motors = make_motors(addresses, state=state, model=model)
    pacing = "unpaced (--fast)" if fast else f"paced at {baud} 8N1"
    banner = (f"servobus sim modbus: {len(motors)} {model} motor(s), addresses "
              f"{','.join(str(m.address) for m in motors)}, {pacing}")
    server = run_server(motors, listen=endpoint, pty=pty, tap=tap_endpoint, paced=not fast,
                        baud=baud, duration=duration, max_clients=max_clients,
                        ready=lambda: click.echo(banner, err=True))
    line = server.line
    click.echo(f"stopped: {line.frames} frame(s), {line.replies} repl(ies) "
               f"({line.exceptions} exception(s)), {line.broadcasts} broadcast(s), "
               f"{line.crc_errors} CRC error(s), {line.discarded} byte(s) discarded, "
               f"{server.runner.rx_dropped} byte(s) lost to full receive buffers, "
               f"{server.cap.refused} connection(s) refused, {server.dropped_clients} "
               "client(s) dropped for not reading", err=True)


def register(group: click.Group) -> None:
    add_sim_command(group, sim_modbus_cmd)
