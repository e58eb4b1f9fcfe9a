"""``servobus shell``: an interactive Python session on a drive or a machine (as odrivetool's).

Bound names: on a drive (``--url``, or the built-in virtual drive) ``axis``, the sync Axis;
on a machine (``--machine FILE``, ``SERVOBUS_MACHINE``, or ``--axis`` alone: the built-in
machine) ``machine`` and every axis by its name (``x``, ``c`` ... where the name is a
Python identifier), plus ``axis`` for the one ``--axis`` names. Always ``servobus``.

Decisions:

* The standard library's ``code`` and ``readline`` (no new dependency): Tab completes
  names, attributes and methods (``rlcompleter``); the history is kept in ``--history
  FILE`` (default ``SERVOBUS_HISTORY``, else ``~/.servobus_history``; ``--history ''``
  keeps none), every line that is not blank, also when the lines come from a pipe.
* A machine is opened as a script's would be for a session (``retry=True``: a link that
  drops comes back), without applying its origin rules: the session cannot tell whether a
  drive was power-cycled since the last one (as the one-shot commands, docs/machine.md).
* Ctrl-C stops every axis the session opened (the running statement is interrupted) and
  the session goes on; SIGTERM stops them and ends it (exit 130); leaving (Ctrl-D,
  ``exit()``, the end of piped input) stops them, then closes the links.
* A servobus error in a statement prints its one line (``error: what - what to do``), any
  other error its traceback; the session goes on.
"""

from __future__ import annotations

import code
import contextlib
import keyword
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from types import CodeType
from typing import Any

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import Interrupted, describe
from servobus.cli.open_axis import open_axis
from servobus.cli.output import note
from servobus.errors import ServobusError

HISTORY_ENV = "SERVOBUS_HISTORY"
HISTORY_LENGTH = 1000
PS1, PS2 = "servobus> ", "... "


def history_path(option: str | None) -> Path | None:
    """--history, else SERVOBUS_HISTORY, else ~/.servobus_history; "" means none."""
    chosen = option if option is not None else os.environ.get(HISTORY_ENV)
    if chosen is None:
        return Path.home() / ".servobus_history"
    return Path(chosen).expanduser() if chosen.strip() else None


class Session(code.InteractiveConsole):
    """The console: Ctrl-C stops the axes, servobus errors print one line (module doc)."""

    def __init__(self, namespace: dict[str, Any], stop: Callable[[], str],
                 prompts: bool, history: Callable[[str], None]) -> None:
        super().__init__(namespace, filename="<servobus shell>")
        self._stop = stop
        self._prompts = prompts
        self._history = history

    def raw_input(self, prompt: str = "") -> str:
        line = input(prompt if self._prompts else "")
        if line.strip():
            self._history(line)
        return line

    def runcode(self, code: CodeType) -> None:
        try:
            exec(code, self.locals)
        except SystemExit:
            raise
        except Interrupted:  # SIGTERM: the session ends (the command stops the axes)
            raise
        except KeyboardInterrupt:
            self.interrupted()
        except BaseException:
            self.showtraceback()

    def showtraceback(self) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, ServobusError):
            self.write(describe(exc)[1] + "\n")
            return
        super().showtraceback()

    def interrupted(self) -> None:
        """Ctrl-C: stop every axis, say so, and go on."""
        self.write(f"\nKeyboardInterrupt: {self._stop()}\n")

    def loop(self) -> None:
        """Read and run statements until the end of input or exit()."""
        more = False
        while True:
            try:
                line = self.raw_input(PS2 if more else PS1)
            except EOFError:
                if self._prompts:
                    self.write("\n")
                return
            except Interrupted:
                raise
            except KeyboardInterrupt:
                self.resetbuffer()
                more = False
                self.interrupted()
                continue
            more = self.push(line)


@contextlib.contextmanager
def readline_on(namespace: dict[str, Any], path: Path | None) -> Iterator[Callable[[str], None]]:
    """Tab completion on ``namespace`` and the history file while the session runs; yields
    what keeps one line in the history. Without readline (Windows): neither."""
    try:
        import readline
        import rlcompleter
    except ImportError:  # pragma: no cover - no readline on this platform
        yield lambda line: None
        return
    previous = readline.get_completer()
    readline.set_completer(rlcompleter.Completer(namespace).complete)
    binding = "bind ^I rl_complete" if "libedit" in (readline.__doc__ or "") else \
        "tab: complete"
    readline.parse_and_bind(binding)
    readline.set_auto_history(False)
    readline.clear_history()
    if path is not None and path.exists():
        with contextlib.suppress(OSError):
            readline.read_history_file(str(path))
    readline.set_history_length(HISTORY_LENGTH)
    try:
        yield readline.add_history
    finally:
        if path is not None:
            try:
                readline.write_history_file(str(path))
            except OSError as exc:
                note(f"note: the shell's history was not kept ({path}: {exc.strerror})")
        readline.clear_history()
        readline.set_auto_history(True)
        readline.set_completer(previous)


@contextlib.contextmanager
def bound(ctx: CliContext) -> Iterator[tuple[dict[str, Any], str, Callable[[], str]]]:
    """The session's names, a line saying what they are, and what stops every axis; the
    axes are stopped and the links closed on the way out."""
    import servobus

    namespace: dict[str, Any] = {"servobus": servobus}
    if not ctx.machine_mode:
        with open_axis(ctx) as axis:
            namespace["axis"] = axis
            what = (f"axis = drive {axis.drive_id} ({ctx.url}, {axis.family.title} over "
                    f"{axis.protocol})")

            def stop_drive() -> str:
                axis.stop()
                return "the drive was told to stop"

            try:
                yield namespace, what, stop_drive
            finally:
                with contextlib.suppress(Exception):
                    axis.stop()
        return
    from servobus.cli.machine_cli import note_builtin_machine_once, note_origins_skipped
    from servobus.machine import open_machine

    machine = open_machine(ctx.machine_path, retry=True, origins=False)
    try:
        note_origins_skipped(machine)
        namespace["machine"] = machine
        names = [n for n in machine.axes if n.isidentifier() and not keyword.iskeyword(n)
                 and n not in namespace]
        namespace.update({n: machine[n] for n in names})
        if ctx.axis_option is not None:
            namespace["axis"] = machine[ctx.axis_option]
        what = f"machine = {machine.name}; axes {', '.join(names) or '(by machine[NAME])'}"

        def stop_all() -> str:
            failed = {n: e for n, e in machine.stop_all().items() if e is not None}
            return "every axis was told to stop" + (
                f" (not {', '.join(failed)}: offline)" if failed else "")

        yield namespace, what, stop_all
    finally:
        machine.close()  # stops every axis first
    if ctx.machine_path is None:
        note_builtin_machine_once()


@click.command("shell", cls=ServobusCommand)
@click.option("--history", metavar="FILE", default=None,
              help=f"the history file [default: {HISTORY_ENV}, else ~/.servobus_history; '' "
                   "keeps none]")
@pass_cli
def shell_cmd(ctx: CliContext, history: str | None) -> None:
    """An interactive Python session on the drive (`axis`) or the machine (`machine`, and
    each axis by its name), with Tab completion and history.

    Ctrl-C stops every axis and the session goes on; leaving it (Ctrl-D, exit()) stops
    them too."""
    prompts = sys.stdin.isatty()
    path = history_path(history)
    with bound(ctx) as (namespace, what, stop), readline_on(namespace, path) as keep:
        note(f"servobus shell: {what}; servobus. Tab completes; Ctrl-C stops every axis; "
             "Ctrl-D leaves (stopping them)")
        session = Session(namespace, stop, prompts, keep)
        try:
            session.loop()
        except SystemExit as exc:  # exit() in the session: leave it
            if exc.code not in (None, 0):
                raise


def register(group: click.Group) -> None:
    group.add_command(shell_cmd)
