"""``servobus sim dyncan``: virtual DYN CAN drives on a CAN bus served over socketcand.

stdout gets one line, flushed at once, so scripts and tests can read the port::

    listening on socketcand 127.0.0.1:40123
    control on tcp://127.0.0.1:40124          (with --control)

Connect with python-can (``interface="socketcand", host=..., port=..., channel="can0"``) or
``servobus --can socketcand:127.0.0.1:40123 --id 1 status``. Everything else (warnings, one
line per abuse event, statistics) goes to stderr. An address that cannot be bound ends the
command with one ``error: ...`` line, exit code 2.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
from collections.abc import Sequence

import click

from servobus.cli.sim_cmd import add_sim_command
from servobus.cli.sim_control import control_option, start_control
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.node import DynCanNetwork, serve
from servobus.sim.drive import VirtualDrive
from servobus.sim.fleet import make_drives, parse_ids
from servobus.sim.realtime import RealtimeClock
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS, fit_fd_limit, log_to_stderr
from servobus.transport.can_bus import BitTiming
from servobus.transport.socketcand_hub import SocketcandHub, parse_socketcand_address


async def run_socketcand_nodes(drives: Sequence[VirtualDrive], host: str, port: int, *,
                               fast: bool = False, duration: float | None = None,
                               bitrate: int = 1_000_000,
                               max_clients: int = DEFAULT_MAX_CLIENTS,
                               banner: str | None = None,
                               control: tuple[str, int] | None = None,
                               ) -> tuple[DynCanNetwork, SocketcandHub]:
    """Serve ``drives`` as DYN CAN nodes until ``duration`` passes or SIGINT/SIGTERM."""
    network = DynCanNetwork(drives)
    hub = SocketcandHub(host, port, lossless=fast, max_clients=max_clients)
    host, port = await hub.start()
    click.echo(f"listening on socketcand {host}:{port}")
    sys.stdout.flush()
    if banner is not None:
        click.echo(banner, err=True)
    node_port = hub.open_port(timing=None if fast else BitTiming(bitrate), gate=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    if duration is not None:
        loop.call_later(duration, stop.set)
    clock = RealtimeClock(network.drives)
    try:
        controller = start_control(control, network.drives, clock=clock)
        try:
            await serve(network, node_port, clock=clock, stop=stop)
        finally:
            if controller is not None:
                await controller.close()
    finally:
        await hub.close()
    return network, hub


@click.command("dyncan")
@click.option("--socketcand", "address", metavar="HOST:PORT", default="127.0.0.1:0",
              show_default=True, help="serve the CAN bus over socketcand; PORT 0 picks a free port")
@click.option("--ids", default="1", show_default=True, metavar="1,2,3",
              help="drive ids on the bus (1..63)")
@click.option("--fast", is_flag=True, help="no 1 Mbit/s bit-timing model: answer at once")
@click.option("--bitrate", type=click.Choice([str(k * 1000) for k in c.BITRATES_KBIT]),
              callback=lambda _ctx, _param, value: int(value), default="1000000",
              show_default=True, help="bit rate of the timing model")
@click.option("--state", metavar="FILE", default=None,
              help="keep each drive's EEPROM (parameters, config, id) in this JSON file")
@click.option("--model", type=click.Choice(sorted(U.MODELS)), default=U.DEFAULT_MODEL,
              show_default=True, help="drive/motor model")
@click.option("--duration", type=click.FloatRange(min=0.0), default=None, metavar="SECONDS",
              help="stop by itself after this many seconds [default: run until Ctrl-C]")
@click.option("--max-clients", type=click.IntRange(min=1), default=DEFAULT_MAX_CLIENTS,
              show_default=True, help="socketcand clients served at once; more are refused")
@control_option
def sim_dyncan_cmd(address: str, ids: str, fast: bool, bitrate: int, state: str | None,
                   model: str, duration: float | None, max_clients: int,
                   control: tuple[str, int] | None) -> None:
    """Virtual DYN2/DYN4 drives on one CAN bus (DYN CAN protocol, socketcand rawmode)."""
    log_to_stderr()
    try:
        drive_ids = parse_ids(ids)
        host, port = parse_socketcand_address(address)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc)) from None
    if 0 in drive_ids:
        raise click.BadParameter("id 0 is the DYN CAN broadcast id; use 1..63",
                                 param_hint="--ids")
    drives = make_drives(drive_ids, state=state, model=model)
    timing = "unpaced (--fast)" if fast else f"{bitrate / 1e6:g} Mbit/s timing model"
    banner = (f"servobus sim dyncan: {len(drives)} {model} drive(s), ids "
              f"{','.join(str(d.drive_id) for d in drives)}, {timing}")
    max_clients = fit_fd_limit(max_clients)
    network, hub = asyncio.run(run_socketcand_nodes(drives, host, port, fast=fast,
                                                    duration=duration, bitrate=bitrate,
                                                    max_clients=max_clients, banner=banner,
                                                    control=control))
    s = network.stats
    click.echo(f"stopped: {s.frames} frame(s), {s.replies} repl(ies), {s.drive_errors} drive "
               f"error(s), {s.malformed} malformed, {s.alarms_pushed} alarm push(es), "
               f"{hub.frames_lost} frame(s) lost to full receive FIFOs, {hub.cap.refused} "
               f"connection(s) refused, {hub.dropped_clients} client(s) dropped for not "
               f"reading", err=True)


def register(group: click.Group) -> None:
    add_sim_command(group, sim_dyncan_cmd)
