"""A protocol's command-line commands as data (issue 31 item 2).

A protocol's ``cli.py`` declares ``COMMANDS``, a tuple of :class:`Command`: the options of its
``servobus sim <name>`` server and of any command of its own (``discover``, ``io`` of enip),
each with a plain entry point. ``servobus.cli.protocol_cmds`` builds the click commands from
them through the registry (``ProtocolSpec.commands``), so no protocol imports the CLI and the
CLI names no protocol.

Decision: entry points are plain functions, not coroutines - each server chooses its own
event loop (the fine selector, SCHED_FIFO for enip's Class 1 I/O) - called as
``run(io, **values)`` with one keyword per option's ``dest``; ``io`` is the :class:`CommandIO`
the CLI gives (its output and the drive its global options name).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from servobus.axis.sync import Axis


@dataclass(frozen=True)
class Option:
    """One option (or, with ``argument``, a positional argument) of a command.

    ``type`` is ``str``, ``int``, ``float`` or ``bool`` (a flag; ``"--x/--no-x"`` in ``flag``
    gives both spellings). ``parse`` turns the text given into the value the entry point
    receives; an ArgumentRangeError it raises is a usage error naming the option (exit 2).
    """

    #: ``--listen`` (``--realtime/--no-realtime`` for a flag with its negation).
    flag: str
    #: The keyword the entry point receives the value as.
    dest: str
    help: str = ""
    type: type[str] | type[int] | type[float] | type[bool] = str
    default: Any = None
    #: The only values accepted (text, before ``parse``).
    choices: tuple[str, ...] = ()
    #: Inclusive bounds of an ``int`` or ``float``.
    minimum: float | None = None
    maximum: float | None = None
    #: A number of seconds: finite, > 0 (>= 0 with ``allow_zero``), at most ``maximum``.
    seconds: bool = False
    allow_zero: bool = False
    metavar: str | None = None
    show_default: bool = False
    parse: Callable[[Any], Any] | None = None
    #: A positional argument; ``many``: any number of them (a tuple).
    argument: bool = False
    many: bool = False


class CommandIO(Protocol):
    """What a protocol command may ask of the front end that runs it."""

    @property
    def json(self) -> bool:
        """True when the user asked for machine-readable output (``--json``)."""

    def echo(self, text: str = "", *, err: bool = False, nl: bool = True) -> None:
        """One line on stdout (``err``: a remark on stderr); ``nl=False`` keeps the line."""

    def emit_json(self, data: object) -> None:
        """One JSON document on stdout."""

    def open_axis(self) -> AbstractContextManager[Axis]:
        """The drive the global options (``--url`` ...) name, closed on leaving."""


@dataclass(frozen=True)
class Command:
    """One command: ``servobus sim <name>`` when ``sim``, else ``servobus <name>``."""

    name: str
    #: The help text (its first line is the summary ``servobus --help`` lists).
    help: str
    #: ``run(io, **values)``: one keyword per option's ``dest``.
    run: Callable[..., None]
    options: tuple[Option, ...] = ()
    sim: bool = False
    #: Further names, hidden from the help (``sim dyn2``, the name before protocols/).
    aliases: tuple[str, ...] = ()
