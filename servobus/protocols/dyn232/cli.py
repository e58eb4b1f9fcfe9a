"""``servobus sim dyn232``: a virtual DYN2 RS485 line on TCP (serial-to-TCP bridge) or a PTY.

stdout gets one line per endpoint, flushed at once, so scripts and tests can read them::

    listening on tcp://127.0.0.1:40123
    pty /dev/pts/7
    tap on tcp://127.0.0.1:40124
    control on tcp://127.0.0.1:40125

Everything else (drive list, warnings, one line per abuse event, statistics) goes to stderr.
An address that cannot be bound ends the command with one ``error: ...`` line, exit code 2.
The command is data (``COMMANDS``, servobus.axis.cli_spec); the CLI builds it.
"""

from __future__ import annotations

from servobus.axis.cli_spec import Command, CommandIO
from servobus.families.dmm import units as U
from servobus.protocols.dyn232.codec import FACTORY_ID
from servobus.protocols.dyn232.pacing import FINE_COARSE_S
from servobus.protocols.dyn232.server import serve
from servobus.sim.cli_options import (
    CONTROL,
    apply_load,
    line_endpoint,
    serial_line_options,
    sim_banner,
    sim_options,
    stopped_line,
)
from servobus.sim.control_server import start_control
from servobus.sim.dmm.fleet import make_drives, parse_drive_ids
from servobus.sim.line_server import run_in_fine_loop
from servobus.sim.server_limits import fit_fd_limit, log_to_stderr


def run_sim(io: CommandIO, *, listen: tuple[str, int] | None, pty: bool,
            tap: tuple[str, int] | None, ids: tuple[int, ...] | None, fast: bool,
            state: str | None, model: str, duration: float | None, max_clients: int,
            control: tuple[str, int] | None,
            load: str | None, inertia: float | None, resonance: float | None,
            load_torque: float | None, plant: str) -> None:
    """Virtual DYN2/DC2 drives sharing one RS485 line (DYN232M protocol)."""
    log_to_stderr()
    drives = make_drives(ids if ids is not None else (FACTORY_ID,), state=state, model=model)
    apply_load(drives, load=load, inertia=inertia, resonance=resonance,
               load_torque=load_torque, plant=plant)
    banner = sim_banner("dyn232", len(drives), "drive", model, "ids",
                        (d.drive_id for d in drives), fast, "paced at 38400 8N1")

    def ready() -> None:
        io.echo(banner, err=True)
        start_control(control, drives)

    server = run_in_fine_loop(serve(
        drives, listen=line_endpoint(listen, pty), pty=pty, tap=tap, paced=not fast,
        duration=duration, coarse_s=FINE_COARSE_S, max_clients=fit_fd_limit(max_clients),
        ready=ready))
    line = server.line
    io.echo(stopped_line(f"{line.packets} packet(s)", f"{line.checksum_errors} checksum error(s)",
                         f"{line.framing_errors} framing error(s)",
                         f"{server.runner.rx_dropped} byte(s) lost to full receive buffers",
                         f"{server.cap.refused} connection(s) refused",
                         f"{server.dropped_clients} client(s) dropped for not reading"),
            err=True)


COMMANDS = (Command(
    "dyn232", run_sim.__doc__ or "", run_sim, sim=True,
    aliases=("dyn2",),  # the name before protocols/
    options=(
        *serial_line_options(connects="pyserial socket", tap_carries="byte"),
        *sim_options(parse_ids=parse_drive_ids, ids_default=None,
                     ids_help=f"drive ids on the line [default: one drive with the factory id "
                              f"{FACTORY_ID}]",
                     fast_help="no 38400-baud pacing: answer at once",
                     state_help="keep each drive's EEPROM (parameters, config, id) in this JSON "
                                "file",
                     models=U.MODELS, model_default=U.DEFAULT_MODEL, model_help="drive/motor model",
                     clients_help="TCP connections (line and tap) served at once; more are "
                                  "closed at once"),
        CONTROL)),)
