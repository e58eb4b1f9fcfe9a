"""The protocols' commands, built from the registry: ``servobus sim <protocol>`` and any
command of a protocol's own (``servobus discover`` ...).

Each protocol declares its commands as data (``ProtocolSpec.cli`` -> a tuple of
servobus.axis.cli_spec.Command); this module turns every one into a click command, so
the CLI names no protocol and no protocol imports the CLI (issue 31 item 2).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any

import click

from servobus.axis.cli_spec import Command, Option
from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext
from servobus.cli.output import emit_json
from servobus.cli.param_types import Seconds
from servobus.errors import ArgumentRangeError

if TYPE_CHECKING:
    from servobus.axis.sync import Axis


class ClickIO:
    """servobus.axis.cli_spec.CommandIO on click's streams and the global options."""

    def __init__(self, ctx: CliContext) -> None:
        self._ctx = ctx

    @property
    def json(self) -> bool:
        return self._ctx.json

    def echo(self, text: str = "", *, err: bool = False, nl: bool = True) -> None:
        click.echo(text, err=err, nl=nl)

    def emit_json(self, data: object) -> None:
        emit_json(data)

    def open_axis(self) -> AbstractContextManager[Axis]:
        from servobus.cli.open_axis import open_axis

        return open_axis(self._ctx)


def _value_type(option: Option) -> Any:
    """The click parameter type of ``option``'s declared type, choices and bounds."""
    if option.choices:
        return click.Choice(option.choices)
    if option.seconds:
        return Seconds(allow_zero=option.allow_zero, maximum=option.maximum)
    if option.type is int and (option.minimum is not None or option.maximum is not None):
        return click.IntRange(None if option.minimum is None else int(option.minimum),
                              None if option.maximum is None else int(option.maximum))
    if option.type is float and (option.minimum is not None or option.maximum is not None):
        return click.FloatRange(option.minimum, option.maximum)
    return option.type


def _parser(option: Option) -> Callable[[click.Context, click.Parameter, Any], Any] | None:
    """A click callback applying ``option.parse``: its ArgumentRangeError is a usage error
    naming the option, as when the value itself is refused."""
    parse = option.parse
    if parse is None:
        return None

    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        if value is None:
            return None
        try:
            return parse(value)
        except ArgumentRangeError as exc:
            raise click.BadParameter(str(exc), param_hint=option.flag) from None

    return callback


def build_parameter(option: Option) -> click.Parameter:
    """One click option (or argument) from its declaration."""
    if option.argument:
        return click.Argument([option.dest], nargs=-1 if option.many else 1,
                              metavar=option.metavar, type=_value_type(option),
                              callback=_parser(option))
    if option.type is bool:  # ``--x/--no-x`` is a flag to click without being told
        flag: dict[str, Any] = {} if "/" in option.flag else {"is_flag": True}
        return click.Option([option.flag, option.dest], default=bool(option.default),
                            show_default=option.show_default, help=option.help, **flag)
    return click.Option([option.flag, option.dest], type=_value_type(option),
                        default=option.default, show_default=option.show_default,
                        metavar=option.metavar, help=option.help, callback=_parser(option))


def build_command(command: Command) -> click.Command:
    """The click command of ``command``: a sim server is a plain command, a protocol's own
    command on a drive takes the trailing ``--json``/``--debug`` as every drive command does."""

    def callback(**values: Any) -> None:
        ctx = click.get_current_context().find_object(CliContext)
        if ctx is None:  # invoked outside ``servobus`` (a test's own group): no global options
            ctx = CliContext(url_option=None, port=None, can=None, drive_id_option=None,
                             baud=None, json=False, timeout=None)
        command.run(ClickIO(ctx), **values)

    cls = click.Command if command.sim else ServobusCommand
    return cls(command.name, callback=callback, help=command.help,
               params=[build_parameter(o) for o in command.options])


def commands() -> list[Command]:
    """Every protocol's commands, in provider order."""
    from servobus.axis import registry

    return [c for target in registry.provided_list("CLI") for c in registry.load(target)]


def register(group: click.Group) -> None:
    """Add every protocol's commands to ``group`` (``sim`` ones to its ``sim`` group, which
    servobus.cli.sim_cmd registers first); a name already taken is refused."""
    sim = group.commands.get("sim")
    if not isinstance(sim, click.Group):
        raise RuntimeError("servobus.cli.sim_cmd must be registered before the protocols' "
                           "commands")
    for command in commands():
        parent = sim if command.sim else group
        built = build_command(command)
        for name in (command.name, *command.aliases):
            if name in parent.commands:
                raise RuntimeError(f"two commands named {parent.name} {name}")
            if name == command.name:
                parent.add_command(built)
            else:
                hidden = build_command(command)
                hidden.hidden = True
                parent.add_command(hidden, name=name)
