"""Entry point of the ``servobus`` command (also ``python -m servobus``).

:func:`main` turns every failure into one stderr line and a documented exit code
(servobus.cli.failures), and ends quietly (exit 0) when standard output is a pipe its
reader closed (``servobus profile ... | head -3``); ``--debug`` or ``SERVOBUS_DEBUG=1`` adds
the Python traceback and lets third-party libraries log to stderr.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import os
import select
import signal
import sys
import traceback
from types import FrameType
from typing import NoReturn

import click

from servobus import __version__
from servobus.cli.context import MACHINE_ENV, URL_ENV, CliContext
from servobus.cli.failures import Terminated, describe
from servobus.cli.param_types import Seconds

#: Command-group modules; each defines ``register(group: click.Group) -> None``. Protocol
#: packages declare theirs (``sim <protocol>`` ...) as data on their ProtocolSpec;
#: servobus.cli.protocol_cmds builds them from the registry, after these.
COMMAND_MODULES: list[str] = [
    "servobus.cli.sim_cmd",
    "servobus.cli.decode_cmd",
    "servobus.cli.drive_cmds",
    "servobus.cli.params_cmd",
    "servobus.cli.scan_cmd",
    "servobus.cli.demo_cmd",
    "servobus.cli.profile_cmd",
    "servobus.cli.gui_cmd",
    "servobus.cli.serve_cmd",
    "servobus.cli.hal_cmd",
    "servobus.cli.users_cmd",
    "servobus.cli.enable_cmd",
    "servobus.cli.origin_cmd",
    "servobus.cli.jog_cmd",
    "servobus.cli.tune_cmd",
    "servobus.cli.shell_cmd",
]

#: Commands loaded on their own when they are what runs (the rest stay unimported):
#: ``serve`` is a long-running process whose time to ``ready`` counts (issue 36,
#: docs/gateway.md "Start-up time"); the others' modules cost it a third of a second.
ALONE: dict[str, str] = {"serve": "servobus.cli.serve_cmd"}

DEBUG_ENV = "SERVOBUS_DEBUG"
COMPLETE_ENV = "_SERVOBUS_COMPLETE"
#: Loggers whose chatter never reaches the terminal without --debug (python-can's socketcand
#: client logs every failed connect attempt, thousands per second).
QUIET_LOGGERS = ("can",)


class LazyGroup(click.Group):
    """A group whose command modules are imported when first needed: every one of them
    as soon as its commands are listed or looked up, except that looking up a command of
    :data:`ALONE` imports that command's module only."""

    _loading = False
    _loaded = False

    @property  # type: ignore[override]
    def commands(self) -> dict[str, click.Command]:
        if not (self._loading or self._loaded):
            self._load(COMMAND_MODULES, protocols=True)
            self._loaded = True
        return self._commands

    @commands.setter
    def commands(self, value: dict[str, click.Command]) -> None:
        self._commands = value

    def _load(self, modules: list[str], protocols: bool = False) -> None:
        self._loading = True
        try:
            for name in modules:
                importlib.import_module(name).register(self)
            if protocols:  # built from the protocol registry, after the sim group
                from servobus.cli import protocol_cmds

                protocol_cmds.register(self)
        finally:
            self._loading = False

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if not self._loaded and cmd_name in ALONE:
            if cmd_name not in self._commands:
                self._load([ALONE[cmd_name]])
            return self._commands.get(cmd_name)
        return super().get_command(ctx, cmd_name)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--url", "url", metavar="URL", default=None,
              help="the drive: dyn232:///dev/ttyUSB0, dyncan+pcan://PCAN_USBBUS1, sim://dyncan "
                   f"... (docs/axis.md; or {URL_ENV}). Default: the built-in virtual drive.")
@click.option("--port", metavar="PORT", default=None,
              help="shortcut: a serial port or pyserial URL (/dev/ttyUSB0, COM3, "
                   "socket://host:port)")
@click.option("--can", metavar="INTERFACE:CHANNEL", default=None,
              help="shortcut: a CAN bus, e.g. pcan:PCAN_USBBUS1 or socketcand:127.0.0.1:29536")
@click.option("--id", "drive_id", type=click.IntRange(0, 255), default=None,
              help="drive id [default: SERVOBUS_ID, else the protocol's factory id]")
@click.option("--baud", type=click.IntRange(min=1), default=None,
              help="serial baud rate [default: the protocol's]")
@click.option("--timeout", type=Seconds(), default=None,
              help="reply deadline in seconds (> 0)")
@click.option("--machine", "machine", metavar="FILE", default=None,
              help=f"a machine file naming the axes (docs/machine.md; or {MACHINE_ENV})")
@click.option("--axis", "axis", metavar="NAME", default=None,
              help="the machine axis a command acts on (without --machine: the built-in "
                   "virtual machine)")
@click.option("--json", "as_json", is_flag=True,
              help="machine-readable output (also accepted after the command)")
@click.option("--debug", is_flag=True,
              help=f"show Python tracebacks and library logs (or {DEBUG_ENV}=1)")
@click.version_option(__version__, prog_name="servobus")
@click.pass_context
def cli(ctx: click.Context, url: str | None, port: str | None, can: str | None,
        drive_id: int | None, baud: int | None, timeout: float | None, machine: str | None,
        axis: str | None, as_json: bool, debug: bool) -> None:
    """servobus: command, tune and monitor servo drives (or their virtual twins).

    Exit status: 0 done; 1 the drive reports a fault (alarm, drive error); 2 usage or
    connection problem; 130 interrupted (Ctrl-C, SIGTERM; a motion in progress is stopped).
    """
    ctx.obj = CliContext(url_option=url, port=port, can=can, drive_id_option=drive_id,
                         baud=baud, json=as_json, timeout=timeout, machine_option=machine,
                         axis_option=axis)


def debug_requested(args: list[str]) -> bool:
    """``--debug`` anywhere before ``--``, or SERVOBUS_DEBUG set to something true."""
    options = args[:args.index("--")] if "--" in args else args
    env = os.environ.get(DEBUG_ENV, "").strip().lower()
    return "--debug" in options or env not in ("", "0", "false", "no", "off")


def configure_logging(debug: bool) -> None:
    """Library logs go to stderr only with --debug; otherwise they are dropped."""
    if debug:
        logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
        return
    for name in QUIET_LOGGERS:
        logger = logging.getLogger(name)
        logger.setLevel(logging.CRITICAL + 1)
        logger.propagate = False
    root = logging.getLogger()
    if not root.handlers:  # no stray record reaches logging's last-resort stderr handler
        root.addHandler(logging.NullHandler())


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise Terminated()


def main(argv: list[str] | None = None) -> None:
    """Run the command; exit with its status (see servobus.cli.failures for the codes)."""
    args = sys.argv[1:] if argv is None else list(argv)
    if any(key.startswith(COMPLETE_ENV) for key in os.environ):  # shell completion: click's
        cli.main(args, prog_name="servobus")
        return
    debug = debug_requested(args)
    configure_logging(debug)
    previous = signal.signal(signal.SIGTERM, _terminate)
    made: list[click.Context] = []  # its obj: the global options, for link_of
    try:
        with cli.make_context("servobus", args) as ctx:
            made.append(ctx)
            cli.invoke(ctx)
    except click.exceptions.Exit as exc:  # --help, --version, ctx.exit()
        sys.exit(exc.exit_code)
    except click.exceptions.NoArgsIsHelpError as exc:  # `servobus`, `servobus sim`: the help
        click.echo(exc.ctx.get_help())
        sys.exit(0)
    except SystemExit:
        raise
    except BrokenPipeError as exc:
        if not stdout_closed():  # a pipe to something else (a drive's link): a failure
            _fail(exc, debug, made)
        _quiet_stdout()  # `servobus ... | head`: the reader has all it wanted
        sys.exit(0)
    except BaseException as exc:  # the one place every failure is reported
        _fail(exc, debug, made)
    finally:
        signal.signal(signal.SIGTERM, previous)
    sys.exit(0)


def link_of(made: list[click.Context]) -> str | None:
    """The link the command used, for advice that names only what applies there
    (servobus.cli.failures.LINK_ADVICE): ``"machine"`` for a machine file's axis."""
    from servobus.axis.registry import link_kind
    from servobus.axis.url import parse_url

    options = made[0].obj if made else None
    if not isinstance(options, CliContext):
        return None
    try:
        if options.machine_mode:
            return "machine"
        return link_kind(parse_url(options.url))
    except Exception:  # options that are themselves the mistake: the generic advice
        return None


def _fail(exc: BaseException, debug: bool, made: list[click.Context]) -> NoReturn:
    code, line = describe(exc, link_of(made))
    if debug:
        traceback.print_exception(exc)
    click.echo(line, err=True)
    sys.exit(code)


def stdout_closed() -> bool:
    """True when standard output is a pipe whose reader has gone (``| head``): poll reports
    an error on it. Decision: that ends the command quietly with exit 0, like a reader that
    read to the end; a broken pipe anywhere else is a failure like any other."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):
        return False
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


def _quiet_stdout() -> None:
    """Point stdout at /dev/null: the interpreter's last flush must not fail loudly."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
