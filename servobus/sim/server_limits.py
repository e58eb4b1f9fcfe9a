"""Safeguards every simulator server shares (protocol-free): connection cap, bounded output,
file-descriptor budget, exposure warning, one log line per event.

The virtual drive servers move (virtual) motors for anyone who connects, with no
authentication, and must survive clients that flood, never read or open thousands of
connections. The bounds, in one place:

* ``DEFAULT_MAX_CLIENTS`` connections per server (``--max-clients``); one more is accepted
  and closed at once (socketcand first gets ``< error ... >``). The first refusal of an
  episode logs one line; the episode ends when a connection is admitted again.
* ``WRITE_HIGH_WATER`` bytes waiting for a client switch its transport to "paused" (asyncio
  flow control): servers stop reading that client's requests until it reads its replies.
* ``MAX_OUTPUT_BYTES`` waiting for one client (or tap) that cannot be paused (it receives
  traffic it did not ask for): past it the client is dropped with one log line.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import os
import sys

try:
    import resource
except ImportError:  # pragma: no cover - not on Windows
    resource = None  # type: ignore[assignment]

from servobus.errors import ServobusError
from servobus.transport.address import is_loopback

logger = logging.getLogger("servobus.sim")

DEFAULT_MAX_CLIENTS = 1024
WRITE_HIGH_WATER = 64 * 1024
MAX_OUTPUT_BYTES = 1024 * 1024
FD_RESERVE = 64  # descriptors kept for listeners, the state file, the PTY, logging, ...
LISTEN_BACKLOG = 1024  # asyncio's default 100 drops SYNs (1 s client stalls) under a burst


class ListenError(ServobusError, OSError):
    """A server could not bind its address (in use, not local, no permission)."""


def listen_error(what: str, url: str, exc: OSError) -> ListenError:
    """One line: what failed - why - what to do."""
    reason = os.strerror(exc.errno) if exc.errno else str(exc)
    hint = ("another program listens there: stop it or pick another port (0 = any free port)"
            if exc.errno == errno.EADDRINUSE else "check the address")
    return ListenError(f"cannot serve {what} on {url} - {reason}; {hint}")


MOVES_MOTORS = "can move the motors"
SEES_TRAFFIC = "can watch every command and reply"


def warn_if_exposed(what: str, host: str, url: str, consequence: str = MOVES_MOTORS) -> None:
    """One stderr line (log warning) when a server binds beyond loopback."""
    if not is_loopback(host):
        logger.warning("warning: %s on %s is reachable beyond this machine; anyone who can "
                       "connect %s (no authentication)", what, url, consequence)


def fit_fd_limit(max_clients: int) -> int:
    """Raise RLIMIT_NOFILE's soft limit so ``max_clients`` connections fit; return the cap
    that fits (lower than asked, with one log line, when the hard limit is too low)."""
    if resource is None:  # pragma: no cover - Windows
        return max_clients
    try:
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    except (OSError, ValueError):  # pragma: no cover
        return max_clients
    want = max_clients + FD_RESERVE
    if soft != resource.RLIM_INFINITY and soft < want:
        new = want if hard == resource.RLIM_INFINITY else min(want, hard)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (new, hard))
            soft = new
        except (OSError, ValueError):
            pass
    if soft != resource.RLIM_INFINITY and soft < want:
        fit = max(1, soft - FD_RESERVE)
        logger.warning("warning: at most %d connections fit the open-file limit (%d); "
                       "raise it with `ulimit -n` for --max-clients %d", fit, soft, max_clients)
        return fit
    return max_clients


class ClientCap:
    """Counts connections against a cap; logs once per episode of refusals."""

    def __init__(self, limit: int, what: str) -> None:
        if limit < 1:
            raise ValueError("the connection cap must be at least 1")
        self.limit = limit
        self.what = what
        self.count = 0
        self.refused = 0  # total, for the stop summary
        self._refusing = False

    def admit(self) -> bool:
        """Count one new connection; False (and one log line per episode) when full."""
        if self.count >= self.limit:
            self.refused += 1
            if not self._refusing:
                self._refusing = True
                logger.warning("%s: %d connections (the cap, --max-clients): refusing new "
                               "ones until one closes", self.what, self.limit)
            return False
        self._refusing = False
        self.count += 1
        return True

    def release(self) -> None:
        self.count = max(0, self.count - 1)


def output_over_bound(transport: asyncio.WriteTransport, adding: int,
                      bound: int = MAX_OUTPUT_BYTES) -> bool:
    """True when ``adding`` more bytes would take the transport's buffer past ``bound``."""
    return transport.get_write_buffer_size() + adding > bound


def drop_slow_reader(transport: asyncio.WriteTransport, what: str) -> None:
    """Close a client whose unread output reached the bound; one log line."""
    peer = transport.get_extra_info("peername")
    where = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) and len(peer) >= 2 else "?"
    logger.warning("%s: dropped client %s: it left %d KiB unread (limit)", what, where,
                   MAX_OUTPUT_BYTES // 1024)
    transport.abort()


def log_to_stderr() -> None:
    """Show the servers' log lines (one per event) on stderr, as bare lines: for the CLI."""
    if any(getattr(h, "servobus_sim", False) for h in logger.handlers):
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    handler.servobus_sim = True  # type: ignore[attr-defined]
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
