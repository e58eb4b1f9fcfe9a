"""How the ``servobus`` command fails: one stderr line and a documented exit code.

Every failure ends with exactly one line on stderr, ``error: what happened - what to do``,
and one of the exit codes below (README, "Exit codes"). A Python traceback is printed only
with ``--debug`` or ``SERVOBUS_DEBUG=1``.

A ServobusError without a more specific class that already reads ``what - what to do``
(e.g. the servers' port-in-use error) is printed as it is.

Decisions: SIGTERM exits 130 like Ctrl-C (both mean "the user stopped it", and both stop a
motion first); an unexpected exception (a servobus bug) also exits 2, with a line that asks
for ``--debug``; ``params --diff`` (files differ) and ``decode`` (bytes with errors) keep
exit 1 like ``diff`` and ``cmp``.
"""

from __future__ import annotations

import click

from servobus.errors import (
    ArgumentRangeError,
    DriveAlarm,
    DriveError,
    DriveTimeout,
    EepromGuardError,
    InvalidValue,
    LimitError,
    MachineFileError,
    MotionRefused,
    MoveFailed,
    NotSupported,
    ProtocolError,
    ServobusError,
    UnknownScheme,
)
from servobus.families.params_file import ParamsFileError

EXIT_OK = 0
EXIT_FAULT = 1  # the drive reports a fault (DriveAlarm, DriveError), a move failed (MoveFailed)
EXIT_DIFFERENT = 1  # params --diff: drive differs from the file; decode: bytes with errors
EXIT_USAGE = 2  # usage, connection, timeout, file: anything the user can fix at the terminal
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT) or SIGTERM

HELP_HINT = "see `servobus --help`"


class CliError(ServobusError):
    """A failure already phrased for the terminal: what happened and what to do about it."""

    def __init__(self, what: str, todo: str, exit_code: int = EXIT_USAGE) -> None:
        super().__init__(what)
        self.what = what
        self.todo = todo
        self.exit_code = exit_code


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM; ``outcome`` says what was done about it (e.g. the motion stopped)."""

    def __init__(self, signal_name: str = "Ctrl-C", outcome: str = "") -> None:
        super().__init__(signal_name)
        self.signal_name = signal_name
        self.outcome = outcome


class Terminated(Interrupted):
    """SIGTERM, raised by the handler servobus.cli.main installs."""

    def __init__(self) -> None:
        super().__init__("SIGTERM")


#: (exception type, exit code, what to do); the first isinstance match wins.
HINTS: tuple[tuple[type[BaseException], int, str], ...] = (
    (DriveAlarm, EXIT_FAULT,
     "remove the cause (load, wiring, supply), then `servobus reset` (or power-cycle the "
     "drive)"),
    (DriveError, EXIT_FAULT,
     "the drive refused the command: check the value against the drive's manual"),
    (MoveFailed, EXIT_FAULT,
     "enable the drive and remove what stopped it (load, limit, another program), then "
     "move again"),
    (DriveTimeout, EXIT_USAGE, "check --id, power and wiring"),  # LINK_ADVICE first
    (ConnectionRefusedError, EXIT_USAGE,
     "nothing listens there: start the drive's bridge or `servobus sim dyn232 --listen "
     "tcp://HOST:PORT`, or fix the address"),
    (ConnectionError, EXIT_USAGE,
     "check that the drive (or simulator) is still running and connected, then retry"),
    (LimitError, EXIT_USAGE, "give a target inside the axis's soft limits (machine file)"),
    (MachineFileError, EXIT_USAGE, "fix the machine file (docs/machine.md lists every key)"),
    (UnknownScheme, EXIT_USAGE,
     "write SCHEME://TARGET with a scheme above (docs/axis.md, \"Drive URLs\")"),
    (MotionRefused, EXIT_USAGE, HELP_HINT),  # its message says what to do
    (InvalidValue, EXIT_USAGE, "nothing was sent"),  # its own ``todo`` (describe)
    (ArgumentRangeError, EXIT_USAGE, "nothing was sent; give a value inside the range"),
    (NotSupported, EXIT_USAGE, "nothing was sent; this drive or protocol lacks the feature"),
    (EepromGuardError, EXIT_USAGE,
     "nothing was sent; wait a little (the guard protects the EEPROM's write cycles)"),
    (ParamsFileError, EXIT_USAGE,
     "use a file written by `servobus params --save FILE`"),
    (ProtocolError, EXIT_USAGE,
     "check the wiring (noise) and that the other end speaks this protocol"),
    (ServobusError, EXIT_USAGE, HELP_HINT),
    (FileNotFoundError, EXIT_USAGE, "check the path"),
    (PermissionError, EXIT_USAGE,
     "check the permissions (serial ports on Linux: the dialout group)"),
    (OSError, EXIT_USAGE, "check the port, device or file named"),
)


SCAN = "`servobus scan` lists the drives that answer"
#: Advice that depends on the link (servobus.axis.registry.link_kind, or ``"machine"`` when
#: the command acts on a machine file's axis): only the options and checks that apply there
#: (no --baud on CAN, a network or a machine, whose ids and URLs are the file's).
LINK_ADVICE: dict[tuple[type[BaseException], str], str] = {
    (DriveTimeout, "serial"): f"check --id ({SCAN}), power, wiring and --baud",
    (DriveTimeout, "can"): f"check --id ({SCAN}), power, the CAN wiring and termination, the "
                           "bus bitrate, and that the drive speaks this protocol",
    (DriveTimeout, "network"): f"check --id ({SCAN}), that the drive is on and reachable at "
                               "that address, and that it speaks this protocol",
    (DriveTimeout, "virtual"): f"check --id: the virtual drives answer at the URL's ?ids= "
                               f"({SCAN})",
    (DriveTimeout, "machine"): "check the axis's id and url in the machine file "
                               "(`servobus --machine FILE --axis NAME scan` lists the drives "
                               "that answer), power and wiring",
    (ProtocolError, "serial"): "check --baud, the wiring (noise) and that the other end "
                               "speaks this protocol",
    (ProtocolError, "can"): "check the bus bitrate, the wiring (noise, termination) and that "
                            "the other end speaks this protocol",
    (ProtocolError, "network"): "check that the address is the drive's and that it speaks "
                                "this protocol",
    (ProtocolError, "machine"): "check the axis's url in the machine file, the wiring and that "
                                "the other end speaks this protocol",
}


def one_line(text: str) -> str:
    """Collapse whitespace (and newlines) so a message stays on one line."""
    return " ".join(text.split())


def error_line(what: str, todo: str) -> str:
    """``error: what happened - what to do`` on one line."""
    return f"error: {one_line(what).rstrip('.')} - {one_line(todo)}"


def _os_text(exc: OSError) -> str:
    if exc.strerror:
        where = f": {exc.filename}" if exc.filename else ""
        return f"{exc.strerror}{where}"
    return str(exc)


def _what(exc: BaseException) -> str:
    if isinstance(exc, OSError) and not isinstance(exc, ServobusError):
        text = _os_text(exc)
    else:
        text = str(exc)
    text = one_line(text) or type(exc).__name__
    if (isinstance(exc, ConnectionError) and not isinstance(exc, ConnectionRefusedError)
            and not text.lower().startswith("connection lost")):
        text = f"connection lost: {text}"
    return text


def describe(exc: BaseException, link: str | None = None) -> tuple[int, str]:
    """Exit code and the one stderr line for any exception that ends the command; ``link``
    (LINK_ADVICE) picks the advice that applies where it depends on the link."""
    if isinstance(exc, Interrupted):
        outcome = exc.outcome or "nothing was moving"
        return EXIT_INTERRUPTED, error_line(f"interrupted by {exc.signal_name}", outcome)
    if isinstance(exc, KeyboardInterrupt | click.exceptions.Abort):
        return EXIT_INTERRUPTED, error_line("interrupted by Ctrl-C", "nothing was moving")
    if isinstance(exc, CliError):
        return exc.exit_code, error_line(exc.what, exc.todo)
    if isinstance(exc, click.UsageError):
        path = exc.ctx.command_path if exc.ctx is not None else "servobus"
        return exc.exit_code, error_line(exc.format_message(), f"see `{path} --help`")
    if isinstance(exc, click.ClickException):
        return exc.exit_code, one_line(f"error: {exc.format_message()}")
    if isinstance(exc, InvalidValue):
        return EXIT_USAGE, error_line(_what(exc), exc.todo)
    for kind, code, todo in HINTS:
        if isinstance(exc, kind):
            what = _what(exc)
            todo = LINK_ADVICE.get((kind, link or ""), todo)
            if todo == HELP_HINT and " - " in what:  # the message already says what to do
                return code, f"error: {what}"
            return code, error_line(what, todo)
    return EXIT_USAGE, error_line(f"unexpected {type(exc).__name__}: {exc}",
                                  "this is a servobus bug: rerun with --debug and report the "
                                  "traceback")
