"""``servobus sim ...``: virtual drive servers. Sub-commands are added by their modules."""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

import click

from servobus.errors import ArgumentRangeError
from servobus.sim.line_server import parse_listen_url
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS


@click.group("sim")
def sim_group() -> None:
    """Run virtual drives that speak the real wire protocols."""


def register(group: click.Group) -> None:
    from servobus.cli.sim_control_cmd import control_group

    group.add_command(sim_group)
    sim_group.add_command(control_group)  # the control channel client (no protocol)


def add_sim_command(group: click.Group, command: click.Command,
                    aliases: tuple[str, ...] = ()) -> None:
    """Attach ``servobus sim <command>`` (and hidden ``aliases``); sim_cmd registers first."""
    sim = group.commands.get("sim")
    if not isinstance(sim, click.Group):
        raise RuntimeError(f"servobus.cli.sim_cmd must be registered before sim {command.name}")
    sim.add_command(command)
    for alias in aliases:
        hidden = copy.copy(command)
        hidden.hidden = True
        sim.add_command(hidden, name=alias)


# ---------------------------------------------------------------- what every server shares
F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


def sim_options(*, ids_default: str | None, ids_help: str, fast_help: str, state_help: str,
                models: Iterable[str], model_default: str, model_help: str,
                clients_help: str) -> Callable[[F], F]:
    """The options every ``servobus sim <protocol>`` takes, in one decorator: ``--ids``,
    ``--fast``, ``--state``, ``--model``, ``--duration``, ``--max-clients`` (the command
    receives them as ``ids``, ``fast``, ``state``, ``model``, ``duration``, ``max_clients``).
    Only the help texts and defaults differ between protocols."""
    options = [
        click.option("--ids", default=ids_default, show_default=ids_default is not None,
                     metavar="1,2,3", help=ids_help),
        click.option("--fast", is_flag=True, help=fast_help),
        click.option("--state", metavar="FILE", default=None, help=state_help),
        click.option("--model", type=click.Choice(sorted(models)), default=model_default,
                     show_default=True, help=model_help),
        click.option("--duration", type=click.FloatRange(min=0.0), default=None,
                     metavar="SECONDS",
                     help="stop by itself after this many seconds [default: run until Ctrl-C]"),
        click.option("--max-clients", type=click.IntRange(min=1), default=DEFAULT_MAX_CLIENTS,
                     show_default=True, help=clients_help),
    ]

    def decorate(command: F) -> F:
        for option in reversed(options):
            command = option(command)
        return command

    return decorate


def option_value(option: str, parse: Callable[[str], T], value: str) -> T:
    """``parse(value)``; an ArgumentRangeError becomes click's usage error naming ``option``."""
    try:
        return parse(value)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint=option) from None


def listen_option_value(option: str, value: str | None) -> tuple[str, int] | None:
    """A ``tcp://HOST:PORT`` option (None when not given)."""
    return None if value is None else option_value(option, parse_listen_url, value)


def sim_banner(protocol: str, count: int, what: str, model: str, id_word: str,
               ids: Iterable[int], fast: bool, timing: str) -> str:
    """The stderr line a server prints once it is up, e.g. ``servobus sim dyn232: 2 DYN2
    drive(s), ids 1,2, paced at 38400 8N1`` (``unpaced (--fast)`` instead of ``timing``)."""
    return (f"servobus sim {protocol}: {count} {model} {what}(s), {id_word} "
            f"{','.join(str(i) for i in ids)}, {'unpaced (--fast)' if fast else timing}")


def echo_stopped(*counts: str) -> None:
    """The last stderr line of a server: ``stopped: <count>, <count>, ...``."""
    click.echo(f"stopped: {', '.join(counts)}", err=True)


def serial_line_options(*, connects: str, tap_carries: str) -> Callable[[F], F]:
    """``--listen``, ``--pty`` and ``--tap`` of a virtual serial line (``listen``, ``pty``,
    ``tap``; :func:`line_endpoints` parses them). ``connects`` names the client URL that
    reaches ``--listen``, ``tap_carries`` what the tap serves (``byte``, ``frame``)."""
    options = [
        click.option("--listen", metavar="tcp://HOST:PORT", default=None,
                     help=f"serve the line on TCP ({connects}://HOST:PORT connects); PORT 0 "
                          "picks a free port; a missing host means 127.0.0.1  [default: "
                          "tcp://127.0.0.1:0, or none with --pty]"),
        click.option("--pty", is_flag=True,
                     help="serve the line on a pseudo-terminal; prints its path"),
        click.option("--tap", metavar="tcp://HOST:PORT", default=None,
                     help=f"also serve every {tap_carries} of the line (both directions) for "
                          "`servobus sniff`"),
    ]

    def decorate(command: F) -> F:
        for option in reversed(options):
            command = option(command)
        return command

    return decorate


def line_endpoints(listen: str | None, pty: bool, tap: str | None
                   ) -> tuple[tuple[str, int] | None, tuple[str, int] | None]:
    """(line endpoint, tap endpoint) from :func:`serial_line_options`: the line listens on
    127.0.0.1 at a free port unless ``--listen`` names one or ``--pty`` replaces it."""
    endpoint = listen_option_value("--listen", listen)
    if endpoint is None and not pty:
        endpoint = ("127.0.0.1", 0)
    return endpoint, listen_option_value("--tap", tap)
