"""``servobus users add|remove|list --file FILE``: the users of ``servobus serve --users``.

The password is read from standard input when it is not a terminal (one line, for scripts:
``echo "$PW" | servobus users add robot --file users.json``), else prompted twice without
echo. It never appears on the command line (where other users could see it in ``ps``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from servobus.cli.command_class import ServobusCommand
from servobus.gateway.users import Users, check_name, check_password

FILE_OPTION = click.option("--file", "path", type=click.Path(dir_okay=False, path_type=Path),
                           required=True, help="the users file (JSON; created when missing)")


def read_password() -> str:
    if sys.stdin is not None and not sys.stdin.isatty():
        line = sys.stdin.readline(4096)
        return check_password(line.rstrip("\r\n"))
    text: str = click.prompt("password", hide_input=True, confirmation_prompt=True)
    return check_password(text)


@click.group("users")
def users() -> None:
    """Users allowed to command a gateway (servobus serve --users FILE)."""


@users.command("add", cls=ServobusCommand)
@click.argument("name")
@FILE_OPTION
def add(name: str, path: Path) -> None:
    """Add NAME (or replace its password); the password comes from stdin or a prompt."""
    check_name(name)
    table = Users.load_or_empty(path)
    replaced = table.add(name, read_password())
    table.save(path)
    click.echo(f"{'replaced' if replaced else 'added'} user {name} in {path}")


@users.command("remove", cls=ServobusCommand)
@click.argument("name")
@FILE_OPTION
def remove(name: str, path: Path) -> None:
    """Remove NAME from the file."""
    table = Users.load(path)
    table.remove(name)
    table.save(path)
    click.echo(f"removed user {name} from {path}")


@users.command("list", cls=ServobusCommand)
@FILE_OPTION
def list_users(path: Path) -> None:
    """The names in the file (never the hashes)."""
    for name in sorted(Users.load(path).records):
        click.echo(name)


def register(group: click.Group) -> None:
    group.add_command(users)
