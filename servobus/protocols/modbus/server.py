"""Serve one virtual Modbus RTU line of YZ-AIM motors over TCP (serial-to-TCP bridge), a PTY
and a tap: ``servobus sim modbus``.

The mechanics (each TCP client its own host port on the line, PTY, tap, fairness,
backpressure, half-close, connection cap) are :mod:`servobus.sim.line_server`'s; this module
puts the RTU line (:mod:`servobus.protocols.modbus.device`) and its baud-rate runner
(:mod:`servobus.protocols.modbus.pacing`) behind them. The tap carries every frame of the
line in wire order: host frames when their last byte arrived, replies when their last byte
left (``servobus sniff --tap tcp://... --protocol modbus``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TextIO

from servobus.protocols.modbus.device import ModbusLine
from servobus.protocols.modbus.pacing import RtuLineRunner, RtuPort
from servobus.protocols.modbus.timing import DEFAULT_BAUD
from servobus.sim import server_limits as lim
from servobus.sim.line_server import DEFAULT_HOST, LineServer, serve_line
from servobus.sim.wire import COARSE_S
from servobus.sim.yzaim.fleet import record_positions
from servobus.sim.yzaim.motor import YzaimMotor

WHAT = "sim modbus"  # how log lines name this server


class ModbusServer(LineServer[RtuPort]):
    """One virtual RTU line (motors + pacing) with its TCP, PTY and tap endpoints."""

    runner: RtuLineRunner

    def __init__(self, motors: Sequence[YzaimMotor], *, paced: bool = True,
                 baud: int = DEFAULT_BAUD, coarse_s: float | None = None,
                 max_clients: int = lim.DEFAULT_MAX_CLIENTS) -> None:
        self.line = ModbusLine(motors)
        runner = RtuLineRunner(self.line, paced=paced, baud=baud,
                               coarse_s=COARSE_S if coarse_s is None else coarse_s)
        super().__init__(runner, what=WHAT, max_clients=max_clients)

    @property
    def motors(self) -> list[YzaimMotor]:
        return self.line.motors


async def serve(
    motors: Sequence[YzaimMotor],
    *,
    listen: tuple[str, int] | None = (DEFAULT_HOST, 0),
    pty: bool = False,
    tap: tuple[str, int] | None = None,
    paced: bool = True,
    baud: int = DEFAULT_BAUD,
    duration: float | None = None,
    out: TextIO | None = None,
    coarse_s: float | None = None,
    max_clients: int = lim.DEFAULT_MAX_CLIENTS,
    ready: Callable[[], None] | None = None,
) -> ModbusServer:
    """Run a line until SIGINT/SIGTERM or ``duration`` seconds; print where it listens.
    When it stops, each motor records its position (power-off, as ``sim easycan`` does)."""
    server = ModbusServer(motors, paced=paced, baud=baud, coarse_s=coarse_s,
                          max_clients=max_clients)
    try:
        return await serve_line(server, listen=listen, pty=pty, tap=tap, duration=duration,
                                out=out, ready=ready)
    finally:
        record_positions(server.motors)
