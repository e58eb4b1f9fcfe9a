"""Test rig (not a test module): a Modbus client and a virtual RTU line on the in-process pair.

``push=True`` gives the client a push-capable cable (its receive-callback path, as over TCP
and ``sim://``); ``push=False`` a pull-only one (read by the transaction manager's ``pull``,
as over pyserial). The line is unpaced: it answers as soon as a request's last byte is in,
so only the tests about deadlines wait on the wall clock. The manipulator sits on the cable.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from servobus.protocols.modbus.axis import ModbusAxis
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.protocols.modbus.device import ModbusLine
from servobus.protocols.modbus.inprocess import make_motors
from servobus.protocols.modbus.pacing import RtuLineRunner
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.transport.base import Direction
from servobus.transport.pair import Manipulator, PairStream, open_pair
from servobus.transport.trace import TraceRecorder

PATHS = {"push": True, "pull": False}  # pytest ids -> open_pair(push=...)


class Rig:
    """Host client + virtual line on one cable, with the manipulator and traces."""

    def __init__(self, ids: tuple[int, ...], *, push: bool, **client_kw: Any) -> None:
        self.faults = Manipulator()
        self.host, self.device = open_pair(self.faults, push=push)
        self.motors: list[YzaimMotor] = make_motors(ids)
        self.line = ModbusLine(self.motors)
        self.runner = RtuLineRunner(self.line, paced=False)
        self._out: list[bytes] = []
        self.port = self.runner.open_port(self._out.append)
        self.sent: list[bytes] = []  # what the host wrote, before faults
        self.host.add_trace(lambda d, data, t: self.sent.append(data)
                            if d is Direction.TX else None)
        self.wire = TraceRecorder()  # the host end's bytes both ways, with times
        self.host.add_trace(self.wire)
        self.client = AsyncModbusClient(self.host, **client_kw)
        self.trace = TraceRecorder()
        self.client.add_trace(self.trace)

    def motor(self, address: int) -> YzaimMotor:
        return next(m for m in self.motors if m.address == address)

    def axis(self, address: int) -> ModbusAxis:
        return ModbusAxis(self.client, address, owns_client=False)

    async def serve(self, device: PairStream) -> None:
        with contextlib.suppress(ConnectionError):
            while True:
                data = await device.read()
                self.runner.submit(self.port, data)
                out, self._out[:] = list(self._out), []
                for reply in out:
                    await device.write(reply)


@asynccontextmanager
async def rig(ids: tuple[int, ...] = (1,), *, push: bool = True,
              **client_kw: Any) -> AsyncIterator[Rig]:
    r = Rig(ids, push=push, **client_kw)
    task = asyncio.get_running_loop().create_task(r.serve(r.device))
    try:
        yield r
    finally:
        await r.client.close()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        await r.runner.close()
