"""Child processes in tests (``servobus sim ...`` and the like): their stdout read line by
line with a deadline, and a stop that never hangs.

Lines are read from the pipe's descriptor one byte at a time, never through Python's
buffered reader, so ``select()`` sees exactly what is left and a later reader (another
``read_line``, ``communicate``) misses nothing. Works on pipes opened in text or bytes mode.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import time
from typing import Any

Process = subprocess.Popen[Any]


def read_line(proc: Process, prefix: str = "", *, timeout: float = 20.0) -> str:
    """The next stdout line of ``proc`` (stripped), which must start with ``prefix``.

    Fails the test when no whole line comes within ``timeout`` seconds or the process ends
    first (with what it wrote to stderr, when it has ended)."""
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    end = time.monotonic() + timeout
    raw = b""
    while not raw.endswith(b"\n"):
        ready, _, _ = select.select([fd], [], [], max(0.0, end - time.monotonic()))
        byte = os.read(fd, 1) if ready else b""
        if not byte:
            raise AssertionError(f"the process printed no line ({'ended' if ready else 'timeout'}"
                                 f"); got {raw!r}{_stderr_if_ended(proc)}")
        raw += byte
    text = raw.decode().strip()
    assert text.startswith(prefix), text
    return text


def stop_process(proc: Process, *, timeout: float = 15.0) -> str:
    """SIGTERM (when still running), wait at most ``timeout``, then kill; what the process
    wrote to stderr that nobody has read yet (text; empty when stderr is not a pipe)."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
    if isinstance(err, bytes):
        return err.decode(errors="replace")
    return err or ""


def _stderr_if_ended(proc: Process) -> str:
    if proc.poll() is None or proc.stderr is None:
        return ""
    err = proc.stderr.read()
    text = err.decode(errors="replace") if isinstance(err, bytes) else err
    return f"; stderr: {text[-800:]}"
