"""Keys from a terminal for ``servobus jog``: each key as it arrives, no Enter needed.

The terminal is put in cbreak mode while the command runs (no echo, no line editing; Ctrl-C
still raises KeyboardInterrupt) and restored on the way out, whatever ends the command.
Terminals send no key-up: a held key arrives as the auto-repeat of its key-down (after the
repeat delay, X11's 660 ms by default, then some 25-40 keys a second).

Keys, as :meth:`TerminalKeys.read` names them: ``"+"`` for Right and Up, ``"-"`` for Left
and Down (ESC [ C/A/D/B, and ESC O C/A/D/B in the terminal's application mode), ``"quit"``
for q, Q and Ctrl-D, ``"other"`` for anything else.
"""

from __future__ import annotations

import os
import select
import termios
import tty
from collections import deque
from types import TracebackType
from typing import Any, Protocol

PLUS, MINUS, QUIT, OTHER = "+", "-", "quit", "other"
_ARROWS = {b"C": PLUS, b"A": PLUS, b"D": MINUS, b"B": MINUS}
_QUIT_BYTES = (b"q", b"Q", b"\x04")
ESC = 0x1B


class KeySource(Protocol):
    """Where ``jog`` reads its keys: a terminal, or a test's script."""

    def read(self, timeout: float | None) -> str | None:
        """The next key, or None when ``timeout`` seconds pass without one (None: wait)."""


def decode(data: bytes) -> list[str]:
    """The keys in ``data`` (several may arrive in one read while a key repeats)."""
    keys: list[str] = []
    i = 0
    while i < len(data):
        if data[i] == ESC and data[i + 1:i + 2] in (b"[", b"O") and i + 2 < len(data):
            keys.append(_ARROWS.get(data[i + 2:i + 3], OTHER))
            i += 3
            continue
        byte = data[i:i + 1]
        keys.append(QUIT if byte in _QUIT_BYTES else OTHER)
        i += 1
    return keys


class TerminalKeys:
    """The keys of the terminal on ``fd``, in cbreak mode while the ``with`` block runs."""

    def __init__(self, fd: int) -> None:
        self._fd = fd
        self._saved: list[Any] | None = None
        self._pending: deque[str] = deque()

    def __enter__(self) -> TerminalKeys:
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._saved is not None:
            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            self._saved = None

    def read(self, timeout: float | None) -> str | None:
        if not self._pending:
            ready, _, _ = select.select([self._fd], [], [], timeout)
            if not ready:
                return None
            data = os.read(self._fd, 64)
            if not data:  # the terminal closed: as Ctrl-D
                return QUIT
            self._pending.extend(decode(data))
        return self._pending.popleft()
