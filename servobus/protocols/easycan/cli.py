"""``servobus sim easycan``: virtual YZ-AIM motors on a CAN bus served over socketcand.

stdout gets one line per endpoint, flushed at once, so scripts and tests can read them::

    listening on socketcand 127.0.0.1:40123
    control on tcp://127.0.0.1:40124

Connect with python-can (``interface="socketcand", host=..., port=..., channel="can0"``) or
``servobus --url easycan+socketcand://127.0.0.1:40123 --id 1 status``. Everything else goes
to stderr. The motors come set up for communication control (gear numerator 0 saved,
modbus_enable 1 at power-on) unless ``--state`` holds other saved values. The command is
data (``COMMANDS``, servobus.axis.cli_spec); the CLI builds it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence

from servobus.axis.cli_spec import Command, CommandIO
from servobus.families.yzaim import registers as yzaim
from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.protocols.easycan.functions import BITRATE
from servobus.protocols.easycan.server import serve
from servobus.sim.cli_options import (
    CONTROL_YZAIM,
    SOCKETCAND,
    apply_load,
    sim_banner,
    sim_options,
    stopped_line,
)
from servobus.sim.control_server import serve_control
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS, fit_fd_limit, log_to_stderr
from servobus.sim.socketcand_bus import socketcand_bus
from servobus.sim.wall_clock import RealtimeClock
from servobus.sim.yzaim.control import MotorControl
from servobus.sim.yzaim.fleet import make_motors, parse_addresses, record_positions
from servobus.sim.yzaim.motor import YzaimMotor


async def run_socketcand_motors(motors: Sequence[YzaimMotor], host: str, port: int, *,
                                fast: bool = False, duration: float | None = None,
                                max_clients: int = DEFAULT_MAX_CLIENTS,
                                banner: str | None = None,
                                control: tuple[str, int] | None = None) -> EasyCanNetwork:
    """Serve ``motors`` as EasyCan nodes until ``duration`` passes or SIGINT/SIGTERM; with
    ``control`` also the control channel there (servobus.sim.yzaim.control)."""
    network = EasyCanNetwork(motors)
    clock = RealtimeClock(network.motors)
    async with socketcand_bus(host, port, fast=fast, bitrate=BITRATE, duration=duration,
                              max_clients=max_clients, banner=banner) as bus:
        controller = (serve_control(control, MotorControl(network.motors, sync=clock.sync))
                      if control is not None else None)
        try:
            await serve(network, bus.node_port, clock=clock, stop=bus.stop)
        finally:
            if controller is not None:
                await controller.close()
            record_positions(motors)
    return network


def run_sim(io: CommandIO, *, address: tuple[str, int], ids: tuple[int, ...], fast: bool,
            state: str | None, model: str, duration: float | None, max_clients: int,
            control: tuple[str, int] | None, load: str | None, inertia: float | None,
            resonance: float | None, load_torque: float | None, plant: str) -> None:
    """Virtual YZ-AIM motors on one CAN bus (EasyCan protocol, socketcand rawmode)."""
    log_to_stderr()
    host, port = address
    motors = make_motors(ids, state=state, model=model)
    apply_load(motors, load=load, inertia=inertia, resonance=resonance,
               load_torque=load_torque, plant=plant)
    banner = sim_banner("easycan", len(motors), "motor", model, "addresses",
                        (m.address for m in motors), fast, "1 Mbit/s timing model")
    network = asyncio.run(run_socketcand_motors(
        motors, host, port, fast=fast, duration=duration,
        max_clients=fit_fd_limit(max_clients), banner=banner, control=control))
    s = network.stats
    io.echo(stopped_line(f"{s.frames} frame(s)", f"{s.replies} repl(ies)",
                         f"{s.errors} error repl(ies)", f"{s.ignored} ignored",
                         f"{s.cache_dropped} cache frame(s) too fast"), err=True)


COMMANDS = (Command(
    "easycan", run_sim.__doc__ or "", run_sim, sim=True,
    options=(
        SOCKETCAND,
        *sim_options(parse_ids=parse_addresses, ids_default="1",
                     ids_help="motor addresses on the bus (1..254)",
                     fast_help="no 1 Mbit/s bit-timing model: answer at once",
                     state_help="keep each motor's EEPROM (saved registers, position) in this "
                                "JSON file",
                     models=[m.name for m in yzaim.MODELS], model_default=yzaim.DEFAULT_MODEL,
                     model_help="YZ-AIM motor model",
                     clients_help="socketcand clients served at once; more are refused"),
        CONTROL_YZAIM)),)
