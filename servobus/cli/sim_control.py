"""``--control tcp://HOST:PORT`` for every ``servobus sim <protocol>`` server, in two lines:

    @control_option                      # on the click command
    ...
    start_control(control, drives)       # on the server's running event loop, once it is up

The control channel (servobus.sim.dmm.control, docs/sim-control.md) then serves the same drives:
JP3 inputs and outputs, the internal state and faults on demand. It prints
``control on tcp://HOST:PORT`` on stdout (port 0 picks a free one).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import click

from servobus.errors import ArgumentRangeError
from servobus.sim.control_server import ControlServer, print_endpoint
from servobus.sim.dmm.control import DriveControl
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.line_server import parse_listen_url
from servobus.sim.wall_clock import RealtimeClock

F = TypeVar("F", bound=Callable[..., Any])


def _parse(ctx: click.Context, param: click.Parameter, value: str | None
           ) -> tuple[str, int] | None:
    if value is None:
        return None
    try:
        return parse_listen_url(value)
    except ArgumentRangeError as exc:
        raise click.BadParameter(str(exc), param_hint="--control") from None


def control_option(command: F) -> F:
    """The ``--control`` option; the command receives ``control`` as (host, port) or None."""
    return click.option(
        "--control", "control", metavar="tcp://HOST:PORT", default=None, callback=_parse,
        help="also serve the control channel here (JSON lines: analog input, pulse trains, "
             "ENA, outputs, internal state, faults; `servobus sim control`); PORT 0 picks a "
             "free port; a missing host means 127.0.0.1")(command)


def start_control(endpoint: tuple[str, int] | None, drives: Sequence[VirtualDrive], *,
                  clock: RealtimeClock | None = None) -> ControlServer | None:
    """Bind, print where, and serve ``drives`` on the running loop (None: nothing to do).

    ``clock`` is the server's wall-clock mapping when it has one at hand; otherwise one is
    made from the drives' own time. Raises ListenError when the address cannot be bound."""
    if endpoint is None:
        return None
    clock = clock if clock is not None else RealtimeClock(drives)
    server = ControlServer(DriveControl(drives, sync=clock.sync))
    server.bind(*endpoint)
    print_endpoint(server)
    server.start()
    return server
