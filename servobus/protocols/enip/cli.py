"""EtherNet/IP commands: ``servobus sim enip``, ``servobus discover``, ``servobus io``.

Registered from this package (``CLI`` in its ``__init__``), so ``servobus.cli`` names no
protocol. ``sim enip`` prints one line per adapter on stdout, flushed at once, so scripts and
tests can read the ports::

    listening on enip://127.0.0.1:44818 (UDP ListIdentity 44818, Class 1 I/O 2222)

``discover`` prints one line per adapter that answers ListIdentity; ``io`` shows the live
input image of the drive the global options name (``--url enip://...``): one line per frame
when stdout is not a terminal (JSON lines with ``--json``), a live table when it is. Ctrl-C
ends ``io`` normally (exit 0) after a Forward_Close, with the I/O statistics on stderr.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import click

from servobus import fastloop
from servobus.axis.capabilities import Capability
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.open_axis import open_axis
from servobus.cli.output import emit_json, note
from servobus.cli.param_types import Seconds
from servobus.cli.sim_cmd import add_sim_command
from servobus.cli.sim_control import control_option, start_control
from servobus.errors import ArgumentRangeError, NotSupported, ServobusError
from servobus.families.dmm import units as U
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.codec import io
from servobus.protocols.enip.codec.encap import TCP_PORT
from servobus.sim.fine_selector import fine_event_loop
from servobus.thread_priority import request_realtime

if TYPE_CHECKING:
    from servobus.protocols.enip.scanner import InputFrame
    from servobus.protocols.enip.server import EnipServer


# ---------------------------------------------------------------- sim enip
def _ready(servers: list[EnipServer], control: tuple[str, int] | None) -> None:
    """Say where the adapters listen; serve the control channel (JP3 I/O, faults) if asked."""
    _listening(servers)
    if servers:
        start_control(control, [s.drive for s in servers], clock=servers[0].clock)


def _listening(servers: list[EnipServer]) -> None:
    for s in servers:
        click.echo(f"listening on enip://{s.host}:{s.tcp_port} (UDP ListIdentity "
                   f"{s.list_port}, Class 1 I/O {s.udp_port})")
    sys.stdout.flush()


async def run_adapters(hosts: str, tcp_port: int, udp_port: int, state: str | None,
                       model: str, duration: float | None, reset_downtime_s: float,
                       control: tuple[str, int] | None = None) -> None:
    from servobus.protocols.enip.server import serve

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    try:
        await serve(hosts, tcp_port, udp_port, state, model=model, stop=stop,
                         duration=duration, reset_downtime_s=reset_downtime_s,
                         on_ready=lambda servers: _ready(servers, control))
    except OSError as exc:
        raise ServobusError(f"cannot listen on {hosts} (TCP {tcp_port}, UDP {udp_port}): "
                            f"{exc.strerror or exc} - use other ports (0 picks free ones) "
                            "or stop what holds them") from exc


@click.command("enip")
@click.option("--listen", "hosts", default="127.0.0.1", show_default=True,
              metavar="IP[,IP...]", help="one virtual DYN5 per IPv4 address (a daisy chain: "
                                         "127.0.0.1,127.0.0.2,... on Linux loopback)")
@click.option("--tcp-port", type=click.IntRange(0, 65535), default=TCP_PORT,
              show_default=True, help="explicit messaging (and UDP ListIdentity); 0 picks "
                                      "a free port, the same on every address")
@click.option("--udp-port", type=click.IntRange(0, 65535), default=io.UDP_PORT,
              show_default=True, help="Class 1 I/O; 0 picks a free port per address (the "
                                      "Forward_Open reply names it)")
@click.option("--state", metavar="FILE", default=None,
              help="keep each drive's EEPROM (saved by DMMDRV5 on a real drive) in this file")
@click.option("--model", type=click.Choice(sorted(U.MODELS)), default=U.DEFAULT_MODEL,
              show_default=True, help="drive/motor model of the simulation")
@click.option("--reset-downtime", type=Seconds(allow_zero=True), default=dyn5.RESET_DOWNTIME_S,
              show_default=True, help="seconds the adapter is silent after a Reset (0x21)")
@click.option("--duration", type=click.FloatRange(min=0.0), default=None, metavar="SECONDS",
              help="stop by itself after this many seconds [default: run until Ctrl-C]")
@click.option("--realtime/--no-realtime", default=True, show_default=True,
              help="run the adapters' loop at SCHED_FIFO where permitted (root or "
                   "CAP_SYS_NICE): Class 1 frames on time beside CPU-bound work")
@control_option
def sim_enip_cmd(hosts: str, tcp_port: int, udp_port: int, state: str | None, model: str,
                 reset_downtime: float, duration: float | None, realtime: bool,
                 control: tuple[str, int] | None) -> None:
    """Virtual DYN5 drives on EtherNet/IP (explicit messaging, ListIdentity, Class 1 I/O)."""
    from servobus.protocols.enip.server import parse_hosts

    try:
        host_list = parse_hosts(hosts)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint="--listen") from None
    click.echo(f"servobus sim enip: {len(host_list)} virtual DYN5 ({model}) on "
               f"{', '.join(host_list)}", err=True)
    if realtime:  # this thread runs the loop (issue 22: measured in bench_enip)
        request_realtime("servobus sim enip")
    with asyncio.Runner(loop_factory=fine_event_loop) as runner:
        runner.run(run_adapters(hosts, tcp_port, udp_port, state, model, duration,
                                reset_downtime, control))
    click.echo("stopped", err=True)


# ---------------------------------------------------------------- discover
@click.command("discover", cls=ServobusCommand)
@click.argument("addresses", nargs=-1, metavar="[IP...]")
@click.option("--port", type=click.IntRange(1, 65535), default=TCP_PORT, show_default=True,
              help="UDP port the adapters answer ListIdentity on")
@click.option("--timeout", "wait", type=Seconds(maximum=60.0), default=1.0, show_default=True,
              help="seconds to collect replies (a list of addresses ends early once all "
                   "answered)")
@click.option("--broadcast", default="255.255.255.255", show_default=True, metavar="IP",
              help="broadcast address when no IP is given")
@pass_cli
def discover_cmd(ctx: CliContext, addresses: tuple[str, ...], port: int, wait: float,
                 broadcast: str) -> None:
    """Find EtherNet/IP adapters (ListIdentity on UDP; broadcast, or the IPs given)."""
    from servobus.protocols.enip.discover import discover

    targets = [a.strip() for text in addresses for a in text.split(",") if a.strip()]
    found = fastloop.run(discover(targets or None, port=port, timeout=wait,
                                   broadcast=broadcast))
    if ctx.json:
        emit_json([f.as_dict() for f in found])
        return
    for f in found:
        d = f.as_dict()
        click.echo(f"{f.address}:{f.port}  {d['product_name']}  vendor 0x{f.identity.vendor_id:04X}"
                   f"  device type {d['device_type']}  product {d['product_code']}  revision "
                   f"{d['revision']}  serial {d['serial_number']}  state {d['state']}")
    if not found:
        where = ", ".join(targets) if targets else f"broadcast {broadcast}"
        note(f"no EtherNet/IP adapter answered ListIdentity on {where} port {port} "
             f"within {wait:g} s")


# ---------------------------------------------------------------- io
def frame_line(frame: InputFrame) -> str:
    st = frame.status
    flags = ", ".join(x for x in ("enabled" if st.enabled else "free",
                                  "moving" if st.moving else "",
                                  "in position" if st.in_position else "off position",
                                  f"alarm {st.alarm_code}: {st.alarm_text}" if st.alarm else "")
                      if x)
    return (f"seq {frame.sequence:>8}  position {frame.position:>11}  speed {frame.speed:>6} "
            f"rpm  torque {frame.torque:>5}  status 0x{frame.image.status:04X} ({flags})")


@click.command("io", cls=ServobusCommand)
@click.option("--rpi", type=click.FloatRange(dyn5.MIN_RPI_US / 1e3, 10_000.0), default=10.0,
              show_default=True, help="requested packet interval, ms (the DYN5's minimum is 5)")
@click.option("--count", "frames", type=click.IntRange(min=1), default=None,
              help="stop after this many input frames")
@click.option("--duration", type=Seconds(), default=None, help="stop after this many seconds")
@pass_cli
def io_cmd(ctx: CliContext, rpi: float, frames: int | None, duration: float | None) -> None:
    """Live Class 1 input image (position, speed, torque, status) of an EtherNet/IP drive."""
    live = sys.stdout.isatty() and not ctx.json
    with open_axis(ctx) as axis:
        if not axis.supports(Capability.CYCLIC_IO):
            raise NotSupported(f"{axis.family.title} over {axis.protocol} has no cyclic I/O; "
                               "use --url enip://HOST", axis.family.name)
        show = _live_display() if live else None

        def on_frame(frame: InputFrame) -> None:
            if show is not None:
                show(frame)
            elif ctx.json:
                emit_json(frame.as_dict())
            else:
                click.echo(frame_line(frame))

        stopped = ""
        try:
            stats = axis.extra.monitor_io(on_frame, rpi_ms=rpi, frames=frames, duration=duration)
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: the normal end of watching
            stats, stopped = None, getattr(exc, "signal_name", "Ctrl-C")
        if show is not None:
            click.echo()
    if stats is None:
        note(f"stopped by {stopped}")
    else:
        note("I/O: " + ", ".join(f"{k} {v}" for k, v in stats.items()))


def _live_display() -> Callable[[InputFrame], None]:
    """A callable that redraws one status line in place on a terminal, at most 10 times/s."""
    last = [0.0]

    def show(frame: InputFrame) -> None:
        now = time.monotonic()
        if now - last[0] >= 0.1:
            last[0] = now
            click.echo("\r" + frame_line(frame) + "\033[K", nl=False)

    return show


def register(group: click.Group) -> None:
    add_sim_command(group, sim_enip_cmd)
    group.add_command(discover_cmd)
    group.add_command(io_cmd)
