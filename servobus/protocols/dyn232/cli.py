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

from servobus.cli.sim_cmd import (
    add_sim_command,
    echo_stopped,
    line_endpoints,
    option_value,
    serial_line_options,
    sim_banner,
    sim_options,
)
from servobus.cli.sim_control import control_option, start_control
from servobus.families.dmm import units as U
from servobus.protocols.dyn232.codec import FACTORY_ID
from servobus.protocols.dyn232.pacing import FINE_COARSE_S
from servobus.protocols.dyn232.server import serve
from servobus.sim.dmm.fleet import make_drives, parse_drive_ids
from servobus.sim.line_server import run_in_fine_loop
from servobus.sim.server_limits import fit_fd_limit, log_to_stderr


@click.command("dyn232")
@serial_line_options(connects="pyserial socket", tap_carries="byte")
@sim_options(ids_default=None,
             ids_help=f"drive ids on the line [default: one drive with the factory id "
                      f"{FACTORY_ID}]",
             fast_help="no 38400-baud pacing: answer at once",
             state_help="keep each drive's EEPROM (parameters, config, id) in this JSON file",
             models=U.MODELS, model_default=U.DEFAULT_MODEL, model_help="drive/motor model",
             clients_help="TCP connections (line and tap) served at once; more are closed at "
                          "once")
@control_option
def sim_dyn2_cmd(listen: str | None, ids: str | None, pty: bool, fast: bool, state: str | None,
                 tap: str | None, model: str, duration: float | None, max_clients: int,
                 control: tuple[str, int] | None) -> None:
    """Virtual DYN2/DC2 drives sharing one RS485 line (DYN232M protocol)."""
    log_to_stderr()
    drive_ids = option_value("--ids", parse_drive_ids, ids) if ids is not None else (FACTORY_ID,)
    endpoint, tap_endpoint = line_endpoints(listen, pty, tap)
    drives = make_drives(drive_ids, state=state, model=model)
    banner = sim_banner("dyn232", len(drives), "drive", model, "ids",
                        (d.drive_id for d in drives), fast, "paced at 38400 8N1")

    def ready() -> None:
        click.echo(banner, err=True)
        start_control(control, drives)

    server = run_in_fine_loop(serve(
        drives, listen=endpoint, pty=pty, tap=tap_endpoint, paced=not fast, duration=duration,
        coarse_s=FINE_COARSE_S, max_clients=fit_fd_limit(max_clients), ready=ready))
    line = server.line
    echo_stopped(f"{line.packets} packet(s)", f"{line.checksum_errors} checksum error(s)",
                 f"{line.framing_errors} framing error(s)",
                 f"{server.runner.rx_dropped} byte(s) lost to full receive buffers",
                 f"{server.cap.refused} connection(s) refused",
                 f"{server.dropped_clients} client(s) dropped for not reading")


def register(group: click.Group) -> None:
    add_sim_command(group, sim_dyn2_cmd, aliases=("dyn2",))  # the name before protocols/
