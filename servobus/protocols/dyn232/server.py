"""Serve one virtual DYN232M RS485 line over TCP (serial-to-TCP bridge) and/or a PTY.

The mechanics are protocol-free and live in :mod:`servobus.sim.line_server` (TCP hosts,
each its own port on the line; PTY; tap; fairness, backpressure, half-close, connection
cap); this module puts the DYN232M line and its 38400-baud runner behind them:

* each TCP client or the PTY is a :class:`~servobus.protocols.dyn232.pacing.HostPort` of
  the :class:`~servobus.protocols.dyn232.pacing.LineRunner`, so two clients never corrupt
  each other's packets and each receives only the replies to its own packets;
* the tap carries every byte of the line in both directions, in wire order (host packets
  when their last byte arrived, replies when their last byte left);
* paced mode drops bytes beyond each port's receive buffer
  (:mod:`servobus.protocols.dyn232.pacing`).

The server binds 127.0.0.1 unless an address is given explicitly, and warns (one log line)
when told to bind beyond loopback. :func:`serve` is the entry point, as in every protocol's
``server`` module; the CLI runs it on :class:`servobus.sim.fine_selector.FineEpollSelector`
(``run_in_fine_loop``): epoll for any number of connections, with microsecond timeouts so
paced replies are released on time.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TextIO

from servobus.protocols.dyn232.device import Dyn232Line
from servobus.protocols.dyn232.pacing import COARSE_S, HostPort, LineRunner
from servobus.sim import server_limits as lim
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.line_server import DEFAULT_HOST, LineServer, serve_line

WHAT = "sim dyn232"  # how log lines name this server


class Dyn232Server(LineServer[HostPort]):
    """One virtual DYN232M line (drives + pacing) with its TCP, PTY and tap endpoints."""

    runner: LineRunner

    def __init__(self, drives: Sequence[VirtualDrive], *, paced: bool = True,
                 coarse_s: float | None = None,
                 max_clients: int = lim.DEFAULT_MAX_CLIENTS) -> None:
        self.line = Dyn232Line(drives)
        super().__init__(LineRunner(self.line, paced=paced,
                                    coarse_s=COARSE_S if coarse_s is None else coarse_s),
                         what=WHAT, max_clients=max_clients)

    @property
    def drives(self) -> list[VirtualDrive]:
        return self.line.drives


async def serve(
    drives: Sequence[VirtualDrive],
    *,
    listen: tuple[str, int] | None = (DEFAULT_HOST, 0),
    pty: bool = False,
    tap: tuple[str, int] | None = None,
    paced: bool = True,
    duration: float | None = None,
    out: TextIO | None = None,
    coarse_s: float | None = None,
    max_clients: int = lim.DEFAULT_MAX_CLIENTS,
    ready: Callable[[], None] | None = None,
) -> Dyn232Server:
    """Run a line until SIGINT/SIGTERM or ``duration`` seconds; print where it listens.

    ``ready`` is called once every endpoint is up. Raises
    :class:`servobus.sim.server_limits.ListenError` when an address cannot be bound.
    """
    server = Dyn232Server(drives, paced=paced, coarse_s=coarse_s, max_clients=max_clients)
    return await serve_line(server, listen=listen, pty=pty, tap=tap, duration=duration,
                            out=out, ready=ready)
