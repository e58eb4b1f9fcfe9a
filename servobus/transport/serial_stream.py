"""pyserial ports and URLs (/dev/ttyUSB0, COM3, socket://, loop://, rfc2217://) as a ByteStream.

pyserial is blocking. A daemon reader thread blocks in ``port.read`` (short timeout so it
notices shutdown) and hands each chunk to the event loop with ``call_soon_threadsafe``.
Writes go straight to ``port.write`` from the loop thread: a DYN232M packet is at most 7
bytes, which the OS driver buffers at once, so the loop is never blocked for long; a
``write_timeout`` bounds the pathological case (flow control stuck). pyserial supports one
reader thread and one writer thread on the same port (that is how miniterm works).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from typing import Any

import serial

from servobus.errors import ConnectionLost
from servobus.transport.base import Direction
from servobus.transport.buffered import BufferedInput

READ_POLL_S = 0.05  # reader-thread read timeout: bounds how long close() waits for it
WRITE_TIMEOUT_S = 1.0


class SerialStream(BufferedInput):
    """A pyserial port as a :class:`ByteStream` (pull-only: read with ``read()``).

    Create with :meth:`open` on the event loop.
    """

    failed_text = "serial port failed"

    def __init__(self, port: Any, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._port = port
        self._loop = loop
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._reader, name=f"serial-rx {port.name}",
                                        daemon=True)
        self._thread.start()

    @classmethod
    async def open(cls, url: str, *, baud: int, **serial_options: Any) -> SerialStream:
        """Open ``url`` (any pyserial port name or URL) at ``baud``, 8N1.

        ``baud`` is the protocol's to give: the transport knows no protocol's default.
        """
        loop = asyncio.get_running_loop()

        def _open() -> Any:
            return serial.serial_for_url(url, baudrate=baud, bytesize=8, parity="N",
                                         stopbits=1, timeout=READ_POLL_S,
                                         write_timeout=WRITE_TIMEOUT_S, **serial_options)

        try:
            port = await loop.run_in_executor(None, _open)
        except (serial.SerialException, ValueError, OSError) as exc:
            # absent, busy, or a URL pyserial does not know: the port cannot be reached
            # (typed as a lost link: a USB adapter plugged in later opens then)
            raise ConnectionLost(f"cannot open {url!r}: {exc}") from exc
        return cls(port, loop)

    # ------------------------------------------------------------- reader thread
    def _reader(self) -> None:
        port = self._port
        while not self._stop.is_set():
            try:
                data = port.read(max(1, port.in_waiting))
            except Exception as exc:  # port vanished (USB unplugged), socket closed, ...
                if not self._stop.is_set():
                    self._post(None, exc)
                return
            if data:
                self._post(bytes(data), None)

    def _post(self, data: bytes | None, error: BaseException | None) -> None:
        with contextlib.suppress(RuntimeError):  # loop already closed during shutdown
            self._loop.call_soon_threadsafe(self._deliver, data, error)

    def _deliver(self, data: bytes | None, error: BaseException | None) -> None:
        if error is not None:
            self._fail(error)
        elif data:
            self._received(data)

    # ------------------------------------------------------------- ByteStream
    async def write(self, data: bytes) -> None:
        if self._closed:
            raise ConnectionLost("stream is closed")
        if self._traces:
            self._trace(Direction.TX, bytes(data))
        try:
            self._port.write(data)
        except serial.SerialTimeoutException as exc:
            raise ConnectionLost(f"serial write timed out: {exc}") from exc
        except (serial.SerialException, OSError) as exc:
            self._fail(exc)  # a pending or later read() fails at once too
            raise ConnectionLost(f"serial write failed: {exc}") from exc

    async def close(self) -> None:
        if not self._mark_closed():
            return
        self._stop.set()
        with contextlib.suppress(Exception):
            self._port.cancel_read()  # not every URL handler has it; the read timeout bounds it
        await self._loop.run_in_executor(None, self._thread.join, 2 * READ_POLL_S + 1.0)
        with contextlib.suppress(Exception):
            self._port.close()
