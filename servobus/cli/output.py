"""How the CLI prints: ``--json`` or a rich console on stdout, remarks on stderr.

Below every command module (each imports it; it imports no command), so the drive commands
and the machine commands print alike without importing each other.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Mapping
from typing import Any

import click
from rich.console import Console

from servobus.cli.context import CliContext


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
    """yes/no for a flag, ``none`` for a value the drive does not have (never ``None``)."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if value is None:
        return "none"
    return str(value)


def id_words(drive_id: int | None) -> str:
    """``id 3``, or ``default id`` for a file or URL that names none (never ``id None``)."""
    return "default id" if drive_id is None else f"id {drive_id}"


def fixed(value: object, digits: int) -> str:
    """``value`` with ``digits`` decimals, never ``-0.000`` (a position of -0.0 or -0.00004
    is shown as 0.000, as a person would write it)."""
    text = f"{value:.{digits}f}"
    return text.lstrip("-") if float(text) == 0 else text  # "-0.000" and "-0.0000" too


def following_words(value: object, unit: str) -> str:
    """The following error as ``status`` shows it (None: the drive reports none)."""
    if not isinstance(value, int | float):
        return "not reported by this drive"
    return f"{fixed(value, 1)} {unit}" if unit == "counts" else f"{fixed(value, 4)} {unit}"


def note(message: str) -> None:
    """A remark for humans on stderr; never mixes into --json output."""
    click.echo(message, err=True)
