"""Entry point of the ``servobus`` command."""

from __future__ import annotations

import importlib
import sys

import click

from servobus import __version__
from servobus.cli.context import CliContext
from servobus.errors import ServobusError
from servobus.protocols.dyn232.codec import MAX_DRIVE_ID

#: Command-group modules; each defines ``register(group: click.Group) -> None``.
COMMAND_MODULES: list[str] = [
    "servobus.cli.sim_cmd",
    "servobus.protocols.dyn232.sim_cmd",
    "servobus.protocols.dyncan.sim_cmd",
    "servobus.cli.decode_cmd",
    "servobus.cli.drive_cmds",
    "servobus.cli.params_cmd",
    "servobus.cli.scan_cmd",
    "servobus.cli.demo_cmd",
    "servobus.cli.profile_cmd",
]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--port", metavar="URL", default=None,
              help="pyserial port or URL (/dev/ttyUSB0, COM3, socket://host:port, loop://). "
                   "Default: the embedded virtual drive (sim://dyn2).")
@click.option("--id", "drive_id", type=click.IntRange(0, MAX_DRIVE_ID), default=0,
              show_default=True, help="drive id")
@click.option("--baud", type=int, default=None, help="serial baud rate [default: the protocol's]")
@click.option("--can", metavar="INTERFACE:CHANNEL", default=None,
              help="talk DYN CAN instead, e.g. socketcand:127.0.0.1:29536 or pcan:PCAN_USBBUS1")
@click.option("--timeout", type=float, default=None, help="reply deadline in seconds")
@click.option("--json", "as_json", is_flag=True, help="machine-readable output")
@click.version_option(__version__, prog_name="servobus")
@click.pass_context
def cli(ctx: click.Context, port: str | None, drive_id: int, baud: int | None, can: str | None,
        timeout: float | None, as_json: bool) -> None:
    """servobus: command, tune and monitor DMM servo drives (or their virtual twins)."""
    ctx.obj = CliContext(port=port, drive_id=drive_id, baud=baud, json=as_json, can=can,
                         timeout=timeout)


for _name in COMMAND_MODULES:
    importlib.import_module(_name).register(cli)


def main() -> None:
    try:
        cli.main(standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except ServobusError as exc:
        click.echo(f"error: {type(exc).__name__}: {exc}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
