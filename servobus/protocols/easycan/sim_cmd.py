"""``servobus sim easycan``: virtual YZ-AIM motors on a CAN bus served over socketcand.

stdout gets one line, flushed at once, so scripts and tests can read the port::

    listening on socketcand 127.0.0.1:40123

Connect with python-can (``interface="socketcand", host=..., port=..., channel="can0"``) or
``servobus --url easycan+socketcand://127.0.0.1:40123 --id 1 status``. Everything else goes
to stderr. The motors come set up for communication control (gear numerator 0 saved,
modbus_enable 1 at power-on) unless ``--state`` holds other saved values.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
from collections.abc import Sequence

import click

from servobus.cli.sim_cmd import add_sim_command
from servobus.errors import ArgumentRangeError
from servobus.families import yzaim
from servobus.protocols.easycan.functions import BITRATE
from servobus.protocols.easycan.node import EasyCanNetwork, serve
from servobus.sim.realtime import RealtimeClock
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS, fit_fd_limit, log_to_stderr
from servobus.sim.yzaim_fleet import make_motors, parse_addresses
from servobus.sim.yzaim_motor import YzaimMotor
from servobus.transport.can_bus import BitTiming
from servobus.transport.socketcand_hub import SocketcandHub, parse_socketcand_address


async def run_socketcand_motors(motors: Sequence[YzaimMotor], host: str, port: int, *,
                                fast: bool = False, duration: float | None = None,
                                max_clients: int = DEFAULT_MAX_CLIENTS,
                                banner: str | None = None) -> EasyCanNetwork:
    """Serve ``motors`` as EasyCan nodes until ``duration`` passes or SIGINT/SIGTERM."""
    network = EasyCanNetwork(motors)
    hub = SocketcandHub(host, port, lossless=fast, max_clients=max_clients)
    host, port = await hub.start()
    click.echo(f"listening on socketcand {host}:{port}")
    sys.stdout.flush()
    if banner is not None:
        click.echo(banner, err=True)
    node_port = hub.open_port(timing=None if fast else BitTiming(BITRATE), gate=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    if duration is not None:
        loop.call_later(duration, stop.set)
    try:
        await serve(network, node_port, clock=RealtimeClock(network.motors), stop=stop)
    finally:
        for motor in motors:  # 1: "communication mode: power-off record position"
            motor.store.record_position(motor.position)
        await hub.close()
    return network


@click.command("easycan")
@click.option("--socketcand", "address", metavar="HOST:PORT", default="127.0.0.1:0",
              show_default=True, help="serve the CAN bus over socketcand; PORT 0 picks a free port")
@click.option("--ids", default="1", show_default=True, metavar="1,2,3",
              help="motor addresses on the bus (1..254)")
@click.option("--fast", is_flag=True, help="no 1 Mbit/s bit-timing model: answer at once")
@click.option("--state", metavar="FILE", default=None,
              help="keep each motor's EEPROM (saved registers, position) in this JSON file")
@click.option("--model", type=click.Choice([m.name for m in yzaim.MODELS]),
              default=yzaim.DEFAULT_MODEL, show_default=True, help="YZ-AIM motor model")
@click.option("--duration", type=click.FloatRange(min=0.0), default=None, metavar="SECONDS",
              help="stop by itself after this many seconds [default: run until Ctrl-C]")
@click.option("--max-clients", type=click.IntRange(min=1), default=DEFAULT_MAX_CLIENTS,
              show_default=True, help="socketcand clients served at once; more are refused")
def sim_easycan_cmd(address: str, ids: str, fast: bool, state: str | None, model: str,
                    duration: float | None, max_clients: int) -> None:
    """Virtual YZ-AIM motors on one CAN bus (EasyCan protocol, socketcand rawmode)."""
    log_to_stderr()
    try:
        addresses = parse_addresses(ids)
        host, port = parse_socketcand_address(address)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc)) from None
    motors = make_motors(addresses, state=state, model=model)
    timing = "unpaced (--fast)" if fast else "1 Mbit/s timing model"
    banner = (f"servobus sim easycan: {len(motors)} {model} motor(s), addresses "
              f"{','.join(str(m.address) for m in motors)}, {timing}")
    network = asyncio.run(run_socketcand_motors(
        motors, host, port, fast=fast, duration=duration,
        max_clients=fit_fd_limit(max_clients), banner=banner))
    s = network.stats
    click.echo(f"stopped: {s.frames} frame(s), {s.replies} repl(ies), {s.errors} error "
               f"repl(ies), {s.ignored} ignored, {s.cache_dropped} cache frame(s) too fast",
               err=True)


def register(group: click.Group) -> None:
    add_sim_command(group, sim_easycan_cmd)
