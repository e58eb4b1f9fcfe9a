"""EtherNet/IP commands: ``servobus sim enip``, ``servobus discover``, ``servobus io``.

Declared as data (``COMMANDS``, servobus.axis.cli_spec) and built by the CLI through the
registry, so ``servobus.cli`` names no protocol and this package imports no front end.
``sim enip`` prints one line per adapter on stdout, flushed at once, so scripts and tests can
read the ports::

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
from typing import TYPE_CHECKING, Any

from servobus import fastloop
from servobus.axis.capabilities import Capability
from servobus.axis.cli_spec import Command, CommandIO, Option
from servobus.errors import NotSupported, ServobusError
from servobus.families.dmm import units as U
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.codec import io as cip_io
from servobus.protocols.enip.codec.encap import TCP_PORT
from servobus.sim.cli_options import CONTROL, LOAD_OPTIONS, apply_load
from servobus.sim.control_server import start_control
from servobus.sim.fine_selector import fine_event_loop
from servobus.thread_priority import request_realtime

if TYPE_CHECKING:
    from servobus.protocols.enip.scanner import InputFrame
    from servobus.protocols.enip.server import EnipServer


# ---------------------------------------------------------------- sim enip
def _ready(servers: list[EnipServer], control: tuple[str, int] | None,
           load: dict[str, Any] | None = None) -> None:
    """Give the drives their load (``--load`` ...), say where the adapters listen; serve the
    control channel (JP3 I/O, faults) if asked."""
    if load:
        apply_load([s.drive for s in servers], **load)
    _listening(servers)
    if servers:
        start_control(control, [s.drive for s in servers], clock=servers[0].clock)


def _listening(servers: list[EnipServer]) -> None:
    for s in servers:
        print(f"listening on enip://{s.host}:{s.tcp_port} (UDP ListIdentity "
                   f"{s.list_port}, Class 1 I/O {s.udp_port})")
    sys.stdout.flush()


async def run_adapters(hosts: str, tcp_port: int, udp_port: int, state: str | None,
                       model: str, duration: float | None, reset_downtime_s: float,
                       control: tuple[str, int] | None = None,
                       load: dict[str, Any] | None = None) -> None:
    from servobus.protocols.enip.server import serve

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    try:
        await serve(hosts, tcp_port, udp_port, state, model=model, stop=stop,
                         duration=duration, reset_downtime_s=reset_downtime_s,
                         on_ready=lambda servers: _ready(servers, control, load))
    except OSError as exc:
        raise ServobusError(f"cannot listen on {hosts} (TCP {tcp_port}, UDP {udp_port}): "
                            f"{exc.strerror or exc} - use other ports (0 picks free ones) "
                            "or stop what holds them") from exc


def checked_hosts(text: str) -> str:
    """``--listen``: the text, once it names IPv4 addresses (ArgumentRangeError if not)."""
    from servobus.protocols.enip.server import parse_hosts

    parse_hosts(text)
    return text


def run_sim(io: CommandIO, *, hosts: str, tcp_port: int, udp_port: int, state: str | None,
            model: str, reset_downtime: float, duration: float | None, realtime: bool,
            control: tuple[str, int] | None, load: str | None, inertia: float | None,
            resonance: float | None, load_torque: float | None, plant: str) -> None:
    """Virtual DYN5 drives on EtherNet/IP (explicit messaging, ListIdentity, Class 1 I/O)."""
    from servobus.protocols.enip.server import parse_hosts

    load_options: dict[str, Any] = {"load": load, "inertia": inertia, "resonance": resonance,
                                    "load_torque": load_torque, "plant": plant}
    apply_load([], **load_options)  # a bad load is a usage error before anything listens
    host_list = parse_hosts(hosts)
    io.echo(f"servobus sim enip: {len(host_list)} virtual DYN5 ({model}) on "
            f"{', '.join(host_list)}", err=True)
    if realtime:  # this thread runs the loop (issue 22: measured in bench_enip)
        request_realtime("servobus sim enip")
    with asyncio.Runner(loop_factory=fine_event_loop) as runner:
        runner.run(run_adapters(hosts, tcp_port, udp_port, state, model, duration,
                                reset_downtime, control, load_options))
    io.echo("stopped", err=True)


SIM_OPTIONS = (
    Option("--listen", "hosts", "one virtual DYN5 per IPv4 address (a daisy chain: "
                                "127.0.0.1,127.0.0.2,... on Linux loopback)",
           default="127.0.0.1", show_default=True, metavar="IP[,IP...]", parse=checked_hosts),
    Option("--tcp-port", "tcp_port", "explicit messaging (and UDP ListIdentity); 0 picks a free "
                                     "port, the same on every address",
           type=int, minimum=0, maximum=65535, default=TCP_PORT, show_default=True),
    Option("--udp-port", "udp_port", "Class 1 I/O; 0 picks a free port per address (the "
                                     "Forward_Open reply names it)",
           type=int, minimum=0, maximum=65535, default=cip_io.UDP_PORT, show_default=True),
    Option("--state", "state", "keep each drive's EEPROM (saved by DMMDRV5 on a real drive) in "
                               "this file", metavar="FILE"),
    Option("--model", "model", "drive/motor model of the simulation",
           choices=tuple(sorted(U.MODELS)), default=U.DEFAULT_MODEL, show_default=True),
    Option("--reset-downtime", "reset_downtime", "seconds the adapter is silent after a Reset "
                                                 "(0x21)",
           type=float, seconds=True, allow_zero=True, default=dyn5.RESET_DOWNTIME_S,
           show_default=True),
    Option("--duration", "duration",
           "stop by itself after this many seconds [default: run until Ctrl-C]",
           type=float, minimum=0.0, metavar="SECONDS"),
    Option("--realtime/--no-realtime", "realtime",
           "run the adapters' loop at SCHED_FIFO where permitted (root or CAP_SYS_NICE): "
           "Class 1 frames on time beside CPU-bound work",
           type=bool, default=True, show_default=True),
    CONTROL,
    *LOAD_OPTIONS,
)


# ---------------------------------------------------------------- discover
def run_discover(io: CommandIO, *, addresses: tuple[str, ...], port: int, wait: float,
                 broadcast: str) -> None:
    """Find EtherNet/IP adapters (ListIdentity on UDP; broadcast, or the IPs given)."""
    from servobus.protocols.enip.discover import discover

    targets = [a.strip() for text in addresses for a in text.split(",") if a.strip()]
    found = fastloop.run(discover(targets or None, port=port, timeout=wait,
                                   broadcast=broadcast))
    if io.json:
        io.emit_json([f.as_dict() for f in found])
        return
    for f in found:
        d = f.as_dict()
        io.echo(f"{f.address}:{f.port}  {d['product_name']}  vendor 0x{f.identity.vendor_id:04X}"
                f"  device type {d['device_type']}  product {d['product_code']}  revision "
                f"{d['revision']}  serial {d['serial_number']}  state {d['state']}")
    if not found:
        where = ", ".join(targets) if targets else f"broadcast {broadcast}"
        io.echo(f"no EtherNet/IP adapter answered ListIdentity on {where} port {port} "
                f"within {wait:g} s", err=True)


DISCOVER_OPTIONS = (
    Option("addresses", "addresses", argument=True, many=True, metavar="[IP...]"),
    Option("--port", "port", "UDP port the adapters answer ListIdentity on", type=int,
           minimum=1, maximum=65535, default=TCP_PORT, show_default=True),
    Option("--timeout", "wait", "seconds to collect replies (a list of addresses ends early once "
                                "all answered)",
           type=float, seconds=True, maximum=60.0, default=1.0, show_default=True),
    Option("--broadcast", "broadcast", "broadcast address when no IP is given",
           default="255.255.255.255", show_default=True, metavar="IP"),
)


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


def run_io(io: CommandIO, *, rpi: float, frames: int | None, duration: float | None) -> None:
    """Live Class 1 input image (position, speed, torque, status) of an EtherNet/IP drive."""
    live = sys.stdout.isatty() and not io.json
    with io.open_axis() as axis:
        if not axis.supports(Capability.CYCLIC_IO):
            raise NotSupported(f"{axis.family.title} over {axis.protocol} has no cyclic I/O; "
                               "use --url enip://HOST", axis.family.name)
        show = _live_display(io) if live else None

        def on_frame(frame: InputFrame) -> None:
            if show is not None:
                show(frame)
            elif io.json:
                io.emit_json(frame.as_dict())
            else:
                io.echo(frame_line(frame))

        stopped = ""
        try:
            stats = axis.extra.monitor_io(on_frame, rpi_ms=rpi, frames=frames, duration=duration)
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: the normal end of watching
            stats, stopped = None, getattr(exc, "signal_name", "Ctrl-C")
        if show is not None:
            io.echo()
    if stats is None:
        io.echo(f"stopped by {stopped}", err=True)
    else:
        io.echo("I/O: " + ", ".join(f"{k} {v}" for k, v in stats.items()), err=True)


def _live_display(io: CommandIO) -> Callable[[InputFrame], None]:
    """A callable that redraws one status line in place on a terminal, at most 10 times/s."""
    last = [0.0]

    def show(frame: InputFrame) -> None:
        now = time.monotonic()
        if now - last[0] >= 0.1:
            last[0] = now
            io.echo("\r" + frame_line(frame) + "\033[K", nl=False)

    return show


IO_OPTIONS = (
    Option("--rpi", "rpi", "requested packet interval, ms (the DYN5's minimum is 5)",
           type=float, minimum=dyn5.MIN_RPI_US / 1e3, maximum=10_000.0, default=10.0,
           show_default=True),
    Option("--count", "frames", "stop after this many input frames", type=int, minimum=1),
    Option("--duration", "duration", "stop after this many seconds", type=float, seconds=True),
)

COMMANDS = (
    Command("enip", run_sim.__doc__ or "", run_sim, SIM_OPTIONS, sim=True),
    Command("discover", run_discover.__doc__ or "", run_discover, DISCOVER_OPTIONS),
    Command("io", run_io.__doc__ or "", run_io, IO_OPTIONS),
)
