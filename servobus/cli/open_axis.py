"""Shared plumbing of the drive commands: open the Axis the global options name.

Every command goes through :func:`open_axis`, so ``--url`` (and its shortcuts ``--port`` and
``--can``), ``--id``, ``--baud`` and ``--timeout`` mean the same thing on every protocol.
Printing the results is :mod:`servobus.cli.output`'s.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager, suppress
from typing import TYPE_CHECKING

from servobus.axis.url import parse_url
from servobus.cli.context import CliContext
from servobus.cli.open_failures import check_reachable, open_failure
from servobus.cli.output import note
from servobus.errors import ArgumentRangeError, MachineFileError, MachineLinkError, NotSupported

if TYPE_CHECKING:
    from servobus.axis.sync import Axis
    from servobus.machine import MachineAxis


@contextmanager
def open_axis(ctx: CliContext, drive_id: int | None = None) -> Iterator[Axis]:
    """Connect to the drive the global options name (or the built-in virtual drive).

    Any failure to open the port or bus becomes one CliError naming it and what to do
    (servobus.cli.open_failures); argument errors (a bad id for the protocol) pass through;
    failures after that are the command's own.
    """
    if ctx.machine_mode:  # --machine/--axis: the Axis of that machine axis
        from servobus.cli.machine_cli import open_axis_of_machine

        with open_axis_of_machine(ctx) as machine_axis:
            yield machine_axis
        return
    from servobus.axis import connect  # lazy: keeps `servobus decode` free of the client

    url = parse_url(ctx.url)
    wanted = ctx.drive_id if drive_id is None else drive_id
    check_reachable(url)
    options: dict[str, object] = {}
    if ctx.baud is not None:
        options["baud"] = ctx.baud
    if ctx.timeout is not None:
        options["timeout"] = ctx.timeout
    try:
        axis = connect(ctx.url, drive_id=wanted, **options)
    except (ArgumentRangeError, NotSupported):
        raise
    except Exception as exc:  # whatever the driver raises, one line names the port
        raise open_failure(url, exc) from exc
    _note_id_address(ctx, wanted, axis.id_address, axis.protocol)
    try:
        yield axis
    except BaseException:
        with suppress(Exception):  # the failure that ended the command is the one to report
            axis.close()
        raise
    axis.close()
    if not ctx.url_given:  # after success only: a failure keeps its one stderr line
        note_builtin_once()


@contextmanager
def open_drive_machine(ctx: CliContext) -> Iterator[MachineAxis]:
    """The drive the global options name as a one-axis machine (a bare URL is a machine,
    servobus.machine.open_url_machine): motion that must end by itself (a held ``speed``)
    runs through the machine's leases, on a loop thread of their own. Opening fails as in
    :func:`open_axis`, in one line. The machine closes without a stop: the command stops
    what it started itself (a ``continuous`` speed is left turning on purpose)."""
    from servobus.cli.machine_cli import closed_without_stop
    from servobus.machine import open_url_machine

    url = parse_url(ctx.url)
    check_reachable(url)
    options = {k: v for k, v in (("baud", ctx.baud), ("timeout", ctx.timeout)) if v is not None}
    query = "&".join(f"{k}={v}" for k, v in options.items())
    spelled = ctx.url if not query else f"{ctx.url}{'&' if url.options else '?'}{query}"
    try:
        machine = open_url_machine(spelled, (ctx.drive_id,))
    except (MachineFileError, MachineLinkError) as exc:  # the link's words: unwrap them
        cause = exc.__cause__ if exc.__cause__ is not None else exc
        if isinstance(cause, ArgumentRangeError | NotSupported):
            raise cause from None
        raise open_failure(url, cause) from exc
    with closed_without_stop(machine):
        axis = next(iter(machine.axes.values()))
        core = axis.axis
        if core is not None:
            _note_id_address(ctx, ctx.drive_id, core.id_address, core.protocol)
        yield axis
    if not ctx.url_given:
        note_builtin_once()


def _note_id_address(ctx: CliContext, wanted: int | None, address: str | None,
                     protocol: str) -> None:
    if wanted is not None and address is not None and address not in ctx.url:
        note(f"note: --id {wanted} addresses {address} (on {protocol} the drive id is the "
             "last byte of the address; docs/axis.md, \"Drive ids\")")


_noted: list[bool] = []


def note_builtin_once() -> None:
    """One stderr line: no drive was named, so the command runs on the built-in one."""
    if not _noted:
        _noted.append(True)
        note("note: no drive named (--url, --port, --can or SERVOBUS_URL): this ran on the "
             "built-in virtual drive, which is gone now")


def link_url(ctx: CliContext) -> str:
    """The URL the command talks over: on a machine axis (--machine/--axis) the file's URL
    of that axis, never the global options' (which name no drive then)."""
    if ctx.machine_mode:
        from servobus.cli.machine_cli import chosen_spec

        return chosen_spec(ctx).url
    return ctx.url


def connection_label(ctx: CliContext, axis: Axis | None = None) -> str:
    drive = axis.drive_id if axis is not None else ctx.drive_id
    url = link_url(ctx)
    label = f"{url}, id {drive if drive is not None else 'default'}"
    if ctx.machine_mode:
        from servobus.cli.machine_cli import chosen_axis

        label = f"axis {chosen_axis(ctx)} ({label})"
    address = axis.id_address if axis is not None else None
    return label if address is None or address in url else f"{label} at {address}"
