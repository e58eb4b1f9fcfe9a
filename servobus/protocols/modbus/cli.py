"""``servobus sim modbus``: virtual YZ-AIM motors on one Modbus RTU line, on TCP (a
serial-to-TCP bridge) or a PTY, paced at the baud rate (19200 8N1 by default).

stdout gets one line per endpoint, flushed at once, so scripts and tests can read them::

    listening on tcp://127.0.0.1:40123
    pty /dev/pts/7
    tap on tcp://127.0.0.1:40124
    control on tcp://127.0.0.1:40125

Everything else (motor list, warnings, statistics) goes to stderr. Connect with
``servobus --url modbus+socket://127.0.0.1:40123 --id 1 status`` or pymodbus
(docs/modbus.md). The command is data (``COMMANDS``, servobus.axis.cli_spec).
"""

from __future__ import annotations

from servobus.axis.cli_spec import Command, CommandIO, Option
from servobus.families.yzaim import registers as Y
from servobus.protocols.modbus.inprocess import FACTORY_ADDRESS, make_motors, parse_addresses
from servobus.protocols.modbus.server import serve
from servobus.protocols.modbus.timing import DEFAULT_BAUD
from servobus.sim.cli_options import (
    CONTROL_YZAIM,
    apply_load,
    line_endpoint,
    serial_line_options,
    sim_banner,
    sim_options,
    stopped_line,
)
from servobus.sim.control_server import serve_control
from servobus.sim.line_server import run_in_fine_loop
from servobus.sim.server_limits import fit_fd_limit, log_to_stderr
from servobus.sim.wall_clock import RealtimeClock
from servobus.sim.wire import FINE_COARSE_S
from servobus.sim.yzaim.control import MotorControl


def run_sim(io: CommandIO, *, listen: tuple[str, int] | None, pty: bool,
            tap: tuple[str, int] | None, baud: int, ids: tuple[int, ...], fast: bool,
            state: str | None, model: str, duration: float | None, max_clients: int,
            control: tuple[str, int] | None, load: str | None, inertia: float | None,
            resonance: float | None, load_torque: float | None, plant: str) -> None:
    """Virtual YZ-AIM motors sharing one Modbus RTU line (RS-485 multi-drop)."""
    log_to_stderr()
    motors = make_motors(ids, state=state, model=model)
    apply_load(motors, load=load, inertia=inertia, resonance=resonance,
               load_torque=load_torque, plant=plant)
    banner = sim_banner("modbus", len(motors), "motor", model, "addresses",
                        (m.address for m in motors), fast, f"paced at {baud} 8N1")

    def ready() -> None:
        io.echo(banner, err=True)
        if control is not None:
            clock = RealtimeClock(motors)
            serve_control(control, MotorControl(motors, sync=clock.sync))

    server = run_in_fine_loop(serve(
        motors, listen=line_endpoint(listen, pty), pty=pty, tap=tap, paced=not fast, baud=baud,
        duration=duration, coarse_s=FINE_COARSE_S, max_clients=fit_fd_limit(max_clients),
        ready=ready))
    line = server.line
    io.echo(stopped_line(f"{line.frames} frame(s)",
                         f"{line.replies} repl(ies) ({line.exceptions} exception(s))",
                         f"{line.broadcasts} broadcast(s)", f"{line.crc_errors} CRC error(s)",
                         f"{line.discarded} byte(s) discarded",
                         f"{server.runner.rx_dropped} byte(s) lost to full receive buffers",
                         f"{server.cap.refused} connection(s) refused",
                         f"{server.dropped_clients} client(s) dropped for not reading"),
            err=True)


COMMANDS = (Command(
    "modbus", run_sim.__doc__ or "", run_sim, sim=True,
    options=(
        *serial_line_options(connects="modbus+socket", tap_carries="frame"),
        Option("--baud", "baud", "the line's baud rate (8N1): pacing and the t3.5 frame gap",
               type=int, minimum=300, default=DEFAULT_BAUD, show_default=True),
        *sim_options(parse_ids=parse_addresses, ids_default=str(FACTORY_ADDRESS),
                     ids_help="device addresses on the line (1..254)",
                     fast_help="no baud-rate pacing: answer at once",
                     state_help="keep each motor's EEPROM (saved registers, position) in this "
                                "JSON file",
                     models=Y.MODEL_BY_NAME, model_default=Y.DEFAULT_MODEL,
                     model_help="YZ-AIM motor model",
                     clients_help="TCP connections (line and tap) served at once; more are "
                                  "closed at once"),
        CONTROL_YZAIM)),)
