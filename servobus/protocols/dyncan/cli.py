"""``servobus sim dyncan``: virtual DYN CAN drives on a CAN bus served over socketcand.

stdout gets one line, flushed at once, so scripts and tests can read the port::

    listening on socketcand 127.0.0.1:40123
    control on tcp://127.0.0.1:40124          (with --control)

Connect with python-can (``interface="socketcand", host=..., port=..., channel="can0"``) or
``servobus --can socketcand:127.0.0.1:40123 --id 1 status``. Everything else (warnings, one
line per abuse event, statistics) goes to stderr. An address that cannot be bound ends the
command with one ``error: ...`` line, exit code 2. The command is data (``COMMANDS``,
servobus.axis.cli_spec); the CLI builds it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence

from servobus.axis.cli_spec import Command, CommandIO, Option
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.protocols.dyncan.server import serve
from servobus.sim.cli_options import (
    CONTROL,
    SOCKETCAND,
    apply_load,
    sim_banner,
    sim_options,
    stopped_line,
)
from servobus.sim.control_server import start_control
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.fleet import make_drives, parse_drive_ids
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS, fit_fd_limit, log_to_stderr
from servobus.sim.socketcand_bus import socketcand_bus
from servobus.sim.socketcand_hub import SocketcandHub
from servobus.sim.wall_clock import RealtimeClock


async def run_socketcand_nodes(drives: Sequence[VirtualDrive], host: str, port: int, *,
                               fast: bool = False, duration: float | None = None,
                               bitrate: int = 1_000_000,
                               max_clients: int = DEFAULT_MAX_CLIENTS,
                               banner: str | None = None,
                               control: tuple[str, int] | None = None,
                               ) -> tuple[DynCanNetwork, SocketcandHub]:
    """Serve ``drives`` as DYN CAN nodes until ``duration`` passes or SIGINT/SIGTERM."""
    network = DynCanNetwork(drives)
    async with socketcand_bus(host, port, fast=fast, bitrate=bitrate, duration=duration,
                              max_clients=max_clients, banner=banner) as bus:
        clock = RealtimeClock(network.drives)
        controller = start_control(control, network.drives, clock=clock)
        try:
            await serve(network, bus.node_port, clock=clock, stop=bus.stop)
        finally:
            if controller is not None:
                await controller.close()
    return network, bus.hub


def node_ids(text: str) -> tuple[int, ...]:
    """``--ids`` of DYN CAN nodes: 1..63 (0 is the broadcast id)."""
    ids = parse_drive_ids(text)
    if 0 in ids:
        raise ArgumentRangeError("id 0 is the DYN CAN broadcast id; use 1..63")
    return ids


def run_sim(io: CommandIO, *, address: tuple[str, int], bitrate: int, ids: tuple[int, ...],
            fast: bool, state: str | None, model: str, duration: float | None,
            max_clients: int, control: tuple[str, int] | None,
            load: str | None, inertia: float | None, resonance: float | None,
            load_torque: float | None, plant: str) -> None:
    """Virtual DYN2/DYN4 drives on one CAN bus (DYN CAN protocol, socketcand rawmode)."""
    log_to_stderr()
    host, port = address
    drives = make_drives(ids, state=state, model=model)
    apply_load(drives, load=load, inertia=inertia, resonance=resonance,
               load_torque=load_torque, plant=plant)
    banner = sim_banner("dyncan", len(drives), "drive", model, "ids",
                        (d.drive_id for d in drives), fast,
                        f"{bitrate / 1e6:g} Mbit/s timing model")
    network, hub = asyncio.run(run_socketcand_nodes(drives, host, port, fast=fast,
                                                    duration=duration, bitrate=bitrate,
                                                    max_clients=fit_fd_limit(max_clients),
                                                    banner=banner, control=control))
    s = network.stats
    io.echo(stopped_line(f"{s.frames} frame(s)", f"{s.replies} repl(ies)",
                         f"{s.drive_errors} drive error(s)", f"{s.malformed} malformed",
                         f"{s.alarms_pushed} alarm push(es)",
                         f"{hub.frames_lost} frame(s) lost to full receive FIFOs",
                         f"{hub.cap.refused} connection(s) refused",
                         f"{hub.dropped_clients} client(s) dropped for not reading"), err=True)


COMMANDS = (Command(
    "dyncan", run_sim.__doc__ or "", run_sim, sim=True,
    options=(
        SOCKETCAND,
        Option("--bitrate", "bitrate", "bit rate of the timing model",
               choices=tuple(str(k * 1000) for k in c.BITRATES_KBIT), default="1000000",
               show_default=True, parse=int),
        *sim_options(parse_ids=node_ids, ids_default="1", ids_help="drive ids on the bus (1..63)",
                     fast_help="no 1 Mbit/s bit-timing model: answer at once",
                     state_help="keep each drive's EEPROM (parameters, config, id) in this JSON "
                                "file",
                     models=U.MODELS, model_default=U.DEFAULT_MODEL, model_help="drive/motor model",
                     clients_help="socketcand clients served at once; more are refused"),
        CONTROL)),)
