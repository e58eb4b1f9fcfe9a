"""Shared plumbing of the drive commands: open the Axis the global options name, print results.

Every command goes through :func:`open_axis`, so ``--port``, ``--id``, ``--baud``, ``--can``
and ``--timeout`` mean the same thing everywhere, and DYN CAN works wherever DYN232M does.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, suppress
from typing import TYPE_CHECKING, Any

import click
from rich.console import Console

from servobus.cli.context import CliContext
from servobus.cli.failures import CliError
from servobus.cli.open_failures import (
    can_open_failure,
    check_can_reachable,
    port_open_failure,
)
from servobus.codec import dyncan
from servobus.errors import ArgumentRangeError

if TYPE_CHECKING:
    from servobus.client.axis import Axis


@contextmanager
def open_axis(ctx: CliContext, drive_id: int | None = None) -> Iterator[Axis]:
    """Connect to the drive (or the embedded virtual drive) and close it afterwards.

    Any failure to open the port or bus becomes one CliError naming it and what to do
    (servobus.cli.open_failures); failures after that are the command's own.
    """
    from servobus.client import connect  # lazy: keeps `servobus decode` free of the client

    wanted = ctx.drive_id if drive_id is None else drive_id
    if ctx.can is not None:
        if wanted == dyncan.BROADCAST_ID:
            raise CliError(f"--id {wanted} is the DYN CAN broadcast id; drives answer only to "
                           f"their own id {dyncan.MIN_DRIVE_ID}..{dyncan.MAX_DRIVE_ID}",
                           "give the drive's --id (`servobus --can ... scan` lists them)")
        check_can_reachable(ctx.can)
    try:
        axis = connect(ctx.port, drive_id=wanted,
                       baud=ctx.baud, can=ctx.can, timeout=ctx.timeout)
    except Exception as exc:  # whatever the driver raises, one line names the port
        if ctx.can is None:
            raise port_open_failure(ctx.url, exc) from exc
        if isinstance(exc, ArgumentRangeError):  # e.g. --id 0 (broadcast): not a bus problem
            raise
        raise can_open_failure(ctx.can, exc) from exc
    try:
        yield axis
    except BaseException:
        with suppress(Exception):  # the failure that ended the command is the one to report
            axis.close()
        raise
    axis.close()


def connection_label(ctx: CliContext) -> str:
    if ctx.can:
        return f"DYN CAN {ctx.can}, id {ctx.drive_id}"
    return f"{ctx.url}, id {ctx.drive_id}"


def console(err: bool = False) -> Console:
    """A rich console on the *current* stdout/stderr (so click's CliRunner captures it)."""
    return Console(file=sys.stderr if err else sys.stdout, highlight=False, soft_wrap=True)


def emit_json(data: object) -> None:
    click.echo(json.dumps(data, indent=None, sort_keys=False))


def emit(ctx: CliContext, data: object, render: Callable[[Console], None]) -> None:
    """``--json``: dump ``data``; otherwise let ``render`` draw on a rich console."""
    if ctx.json:
        emit_json(data)
    else:
        render(console())


def kv_text(title: str, rows: Mapping[str, Any]) -> str:
    """A titled two-column block (plain text: no padding, no markup surprises)."""
    width = max((len(k) for k in rows), default=0) + 2
    return "\n".join([title, *(f"  {k:<{width}}{_fmt(v)}" for k, v in rows.items())])


def _fmt(value: object) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    return str(value)


def note(message: str) -> None:
    """A remark for humans on stderr; never mixes into --json output."""
    click.echo(message, err=True)
