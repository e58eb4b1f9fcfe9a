"""Ctrl-C / SIGTERM while a command waits on motion: stop the motor before exiting.

Leaving a motor running because the terminal was closed is the one failure a motion tool
must not have. :func:`stop_on_interrupt` wraps the part of a command that moves the motor;
on Ctrl-C (KeyboardInterrupt) or SIGTERM (:class:`Terminated`, raised by the handler
servobus.cli.main installs) it sends ``Axis.stop()`` - constant speed 0: the drive ramps
down at Max Accel and holds position (DYN2 manual 7.4.2 Turn_ConstSpeed; Max Accel is the
speed-mode soft start, 5.1) - with further
signals ignored until the stop is out, then re-raises as :class:`Interrupted` whose outcome
says on stderr whether the stop was sent. Exit status 130.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol

from servobus.cli.failures import Interrupted, one_line


class Stoppable(Protocol):
    """An Axis, or a machine axis (whose stop ends its lease first, so no target update
    follows the stop)."""

    def stop(self) -> None: ...

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
STOPPED = "motion stopped: the drive ramps down at Max Accel and holds position"


@contextmanager
def _signals_ignored() -> Iterator[None]:
    """Hold further Ctrl-C/SIGTERM off while the stop goes out (main thread only: elsewhere
    Python delivers no signals anyway)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in _SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextmanager
def stop_on_interrupt(axis: Stoppable) -> Iterator[None]:
    """Stop ``axis`` if the block is interrupted (Ctrl-C / SIGTERM); re-raise Interrupted."""
    try:
        yield
    except KeyboardInterrupt as exc:
        name = exc.signal_name if isinstance(exc, Interrupted) else "Ctrl-C"
        with _signals_ignored():
            try:
                axis.stop()
            except Exception as stop_exc:  # reported; the interrupt wins
                outcome = one_line(f"the stop command failed ({stop_exc}): the motor may still "
                                   "be moving, stop it at the drive")
            else:
                outcome = STOPPED
        raise Interrupted(name, outcome) from exc
