"""Issue 31 item 2: the protocols' commands are data on their specs, and one generic layer
(servobus.cli.protocol_cmds) builds them from the registry."""

from __future__ import annotations

import inspect

import click
import pytest
from click.testing import CliRunner

from servobus.axis import registry
from servobus.axis.cli_spec import Command, CommandIO, Option
from servobus.cli import protocol_cmds
from servobus.cli.command_class import ServobusCommand
from servobus.cli.main import cli
from servobus.errors import ArgumentRangeError

DECLARED = [(name, command) for name, spec in registry.specs().items() if spec.cli
            for command in registry.load(spec.cli)]


def test_every_protocol_declares_its_commands() -> None:
    names = {(name, c.name, c.sim) for name, c in DECLARED}
    assert {(p, p, True) for p in registry.specs()} <= names  # servobus sim <protocol>
    assert {("enip", "discover", False), ("enip", "io", False)} <= names


@pytest.mark.parametrize(("protocol", "command"), DECLARED,
                         ids=[f"{p}-{c.name}" for p, c in DECLARED])
def test_the_cli_offers_what_the_protocol_declares(protocol: str, command: Command) -> None:
    sim = cli.commands["sim"]
    assert isinstance(sim, click.Group)
    parent = sim if command.sim else cli
    built = parent.commands[command.name]
    assert isinstance(built, ServobusCommand) is not command.sim
    assert built.help == command.help
    declared = [(o.dest, o.flag.split("/")[0] if not o.argument else None)
                for o in command.options]
    offered = [(p.name, p.opts[0] if isinstance(p, click.Option) else None)
               for p in built.params if p.name not in ("json", "debug")]
    assert offered == declared
    for alias in command.aliases:
        assert parent.commands[alias].hidden


@pytest.mark.parametrize(("protocol", "command"), DECLARED,
                         ids=[f"{p}-{c.name}" for p, c in DECLARED])
def test_an_entry_point_takes_every_declared_option(protocol: str, command: Command) -> None:
    parameters = list(inspect.signature(command.run).parameters)
    assert parameters[0] == "io"
    assert sorted(parameters[1:]) == sorted(o.dest for o in command.options)


def _even(text: str) -> int:
    value = int(text)
    if value % 2:
        raise ArgumentRangeError(f"{value} is odd")
    return value


def _greet(io: CommandIO, *, names: tuple[str, ...], count: int, loud: bool,
           wait: float | None) -> None:
    """Say hello."""
    for name in names:
        io.echo(f"hello {name} x{count} loud={loud} wait={wait}")
    io.echo("done", err=True)


GREET = Command("greet", "Say hello.", _greet, sim=True, aliases=("hi",), options=(
    Option("names", "names", argument=True, many=True),
    Option("--count", "count", "how many", type=str, default="2", parse=_even),
    Option("--loud/--quiet", "loud", type=bool, default=True),
    Option("--wait", "wait", type=float, seconds=True)))


@pytest.fixture
def group(monkeypatch: pytest.MonkeyPatch) -> click.Group:
    """A fresh ``servobus``-like group whose registry declares only GREET."""
    monkeypatch.setattr(protocol_cmds, "commands", lambda: [GREET])
    root = click.Group("root")
    root.add_command(click.Group("sim"))
    protocol_cmds.register(root)
    return root


def test_the_generic_layer_builds_a_declared_command(group: click.Group) -> None:
    result = CliRunner().invoke(group, ["sim", "greet", "ada", "--count", "4", "--quiet",
                                        "--wait", "0.5"])
    assert result.exit_code == 0, result.output
    assert result.stdout == "hello ada x4 loud=False wait=0.5\n"
    assert result.stderr == "done\n"
    alias = CliRunner().invoke(group, ["sim", "hi", "bob"])
    assert alias.stdout == "hello bob x2 loud=True wait=None\n"


@pytest.mark.parametrize(("args", "refusal"), [
    (["--count", "3"], "Invalid value for --count: 3 is odd"),
    (["--wait", "0"], "0 s: must be > 0"),
])
def test_a_refused_value_is_a_usage_error_naming_the_option(
        group: click.Group, args: list[str], refusal: str) -> None:
    result = CliRunner().invoke(group, ["sim", "greet", *args])
    assert result.exit_code == 2 and refusal in result.stderr


def test_a_name_taken_twice_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(protocol_cmds, "commands", lambda: [GREET])
    root = click.Group("root")
    sim = click.Group("sim")
    sim.add_command(click.Command("greet"))
    root.add_command(sim)
    with pytest.raises(RuntimeError, match="two commands named sim greet"):
        protocol_cmds.register(root)
