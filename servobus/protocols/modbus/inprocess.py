"""``sim://modbus``: virtual YZ-AIM motors on an in-process Modbus RTU line, as a ByteStream.

The stream behaves like a serial port wired to the line: paced at 19200 8N1 (half duplex,
replies t3.5 after each request, :mod:`servobus.protocols.modbus.pacing`) unless
``fast=1``; the motors run in wall-clock time.

URL options (``sim://modbus?ids=1,2&fast=1&state=FILE&model=57AIM30C&baud=19200``):

| option | meaning | default |
| --- | --- | --- |
| ``ids`` | device addresses on the line (1..254) | one motor with the id asked for (1 if none) |
| ``fast`` / ``paced`` | ``fast=1``: no wire pacing | paced |
| ``state`` | JSON file keeping each motor's EEPROM (saved registers, position) | none |
| ``model`` | YZ-AIM model (``servobus.families.yzaim.registers.MODELS``) | 57AIM30C |
| ``baud`` | the line's baud rate (pacing and the client's deadlines) | 19200 |

Client options (``timeout``, ``retries``, ``turnaround_s``, ``late_reply_s``,
``frame_gap_s``, ``eeprom_guard``) pass to
:class:`~servobus.protocols.modbus.client.AsyncModbusClient`.
Unpaced (``fast=1``) the client keeps no frame gap unless ``frame_gap_s`` says so: the
in-process line is no wire, and its framer cuts frames by content.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ConnectionLost
from servobus.families.yzaim import registers as Y
from servobus.protocols.modbus.axis import ModbusAxis, check_address
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.protocols.modbus.device import ModbusLine
from servobus.protocols.modbus.pacing import RtuLineRunner, RtuPort
from servobus.protocols.modbus.timing import DEFAULT_BAUD
from servobus.sim.yzaim.fleet import FACTORY_ADDRESS, make_motors, parse_addresses
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.transport.base import Direction
from servobus.transport.buffered import PushInput

__all__ = ["FACTORY_ADDRESS", "SIM_OPTIONS", "SimByteStream", "make_motors", "open_sim_axis",
           "open_sim_stream", "parse_addresses"]

SIM_OPTIONS: dict[str, type] = {
    "ids": str, "fast": bool, "paced": bool, "state": str, "model": str, "baud": int,
    "timeout": float, "retries": int, "turnaround_s": float, "late_reply_s": float,
    "frame_gap_s": float, "eeprom_guard": object,
}


class SimByteStream(PushInput):
    """A ByteStream wired to an in-process virtual RTU line (a ``PushByteStream``)."""

    closed_text = "sim stream is closed"

    def __init__(self, line: ModbusLine, runner: RtuLineRunner) -> None:
        super().__init__()
        self.line = line
        self.runner = runner
        self._port: RtuPort = runner.open_port(self._received)

    @property
    def motors(self) -> list[YzaimMotor]:
        return self.line.motors

    async def write(self, data: bytes) -> None:
        if self._closed:
            raise ConnectionLost("sim stream is closed")
        data = bytes(data)
        if self._traces:
            self._trace(Direction.TX, data)
        self.runner.submit(self._port, data)

    def _before_wait(self) -> None:
        self.runner.start()  # a read() before any write() still runs the line

    async def close(self) -> None:
        if not self._mark_closed():
            return
        self.runner.close_port(self._port)
        await self.runner.close()


def open_sim_stream(*, ids: Sequence[int] = (FACTORY_ADDRESS,), paced: bool = True,
                    motors: Sequence[YzaimMotor] | None = None, state: str | None = None,
                    model: str = Y.DEFAULT_MODEL, baud: int = DEFAULT_BAUD) -> SimByteStream:
    """An in-process virtual line; ``motors`` (if given) replaces ids/state/model."""
    if motors is None:
        parse_addresses(",".join(str(i) for i in ids))  # same validation as URLs
        motors = make_motors(ids, state=state, model=model)
    line = ModbusLine(motors)
    return SimByteStream(line, RtuLineRunner(line, paced=paced, baud=baud))


async def open_sim_axis(url: DriveUrl, *, drive_id: int | None = None,
                        **keywords: Any) -> ModbusAxis:
    """``sim://modbus``: a ModbusAxis on an in-process virtual line (registered in ``SIM``).

    Without ``ids`` the line holds one motor with the address asked for (1 when none is)."""
    options = merge_options(url, dict(keywords), SIM_OPTIONS)
    if drive_id is not None:
        check_address(drive_id)
    ids_text = options.pop("ids", None)
    ids = parse_addresses(str(ids_text)) if ids_text is not None else (
        (FACTORY_ADDRESS,) if drive_id is None else (drive_id,))
    paced = not bool(options.pop("fast", False)) and bool(options.pop("paced", True))
    model = str(options.pop("model", Y.DEFAULT_MODEL))
    state = options.pop("state", None)
    baud = options.pop("baud", DEFAULT_BAUD)
    AsyncModbusClient.check_options({"baud": baud, **options})
    assert isinstance(baud, int)
    if not paced:
        options.setdefault("frame_gap_s", 0.0)  # no wire: no silence to keep (docs above)
    stream = open_sim_stream(ids=ids, paced=paced, model=model, baud=baud,
                             state=str(state) if state else None)
    try:
        client = AsyncModbusClient(stream, baud=baud, **options)  # type: ignore[arg-type]
    except BaseException:
        await stream.close()
        raise
    return ModbusAxis(client, ids[0] if drive_id is None else drive_id)
