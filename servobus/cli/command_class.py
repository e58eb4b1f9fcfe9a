"""The click Command class of every ``servobus`` sub-command.

Two things click does not do by itself:

* negative numbers are arguments: ``servobus move -120`` and ``servobus set main_gain -1``
  work without ``--`` (a token that is a number is never taken for an option; any other
  unknown ``-x`` is still refused as an unknown option);
* the global output options are accepted after the command too: ``servobus status --json``
  equals ``servobus --json status`` (also ``--debug``).
"""

from __future__ import annotations

import difflib
import re
from typing import Any

import click

from servobus.cli.context import CliContext

#: A negative number, optionally with a unit suffix (``-120``, ``-2.5rev``, ``-90deg``,
#: ``-12.5mm``).
NUMBER = re.compile(r"-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(counts?|revs?|deg|cmd|mm|rpm)?(/s)?")


def _set_json(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    obj = ctx.find_object(CliContext)
    if value and obj is not None:
        obj.json = True


def _trailing_options() -> list[click.Option]:
    return [
        click.Option(["--json"], is_flag=True, expose_value=False, callback=_set_json,
                     help="machine-readable output (same as the global --json)"),
        # Read by servobus.cli.main before parsing; declared so click accepts it here.
        click.Option(["--debug"], is_flag=True, expose_value=False, hidden=True),
    ]


class ServobusCommand(click.Command):
    """A command with negative-number arguments and the trailing ``--json``/``--debug``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.context_settings = {**self.context_settings, "ignore_unknown_options": True}
        taken = {name for p in self.params for name in p.opts}
        self.params.extend(o for o in _trailing_options() if not taken & set(o.opts))

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        """Refuse unknown options ourselves (click is told to ignore them so that negative
        numbers reach the arguments)."""
        known = {name for p in self.get_params(ctx) for name in (*p.opts, *p.secondary_opts)}
        for token in args:
            if token == "--":
                break
            if not token.startswith("-") or token == "-" or NUMBER.fullmatch(token):
                continue
            if not _is_known(token, known):
                name = token.split("=", 1)[0]
                close = difflib.get_close_matches(name, sorted(known), n=3)
                raise click.NoSuchOption(name, possibilities=close, ctx=ctx)
        return super().parse_args(ctx, args)


def _is_known(token: str, known: set[str]) -> bool:
    if token.startswith("--"):
        return token.split("=", 1)[0] in known
    if token in known:
        return True
    # A cluster of short flags (-hv) or a short option with its value attached (-n5).
    return f"-{token[1]}" in known
