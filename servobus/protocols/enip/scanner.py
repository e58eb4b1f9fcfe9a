"""Class 1 implicit I/O from the scanner (originator) side: ``async with axis.io() as io``.

The DYN5 has one I/O image (manual 5): T->O assembly 100 (position, speed, torque, status;
produced every RPI) and O->T assembly 101 (the enable/disable word behind a run/idle
header). :class:`CyclicIo` opens it with Forward_Open over the axis's explicit session:

* its own UDP socket on the local address that routes to the adapter, named in a Sockaddr
  Info item of type 0x8001 after the unconnected data item (scanner and adapter cannot both
  own UDP 2222 on one host: the "Class 1 on one host" rule, docs/enip.md); O->T goes to
  the 0x8000 sockaddr of the reply when the adapter names one, else to its port 2222;
* the connection path ``20 04 24 00 2C 65 2C 64`` (config instance 0, consumed point 101,
  produced point 100), O->T size 10 and T->O size 18 (sequence count included), the same
  RPI both ways, point-to-point, scheduled priority, class 1 cyclic;
* O->T frames every RPI on absolute times (a late tick does not shift the grid; every
  connection on the loop shares one timer, ``production.py``), run bit set. The word
  starts at 0 (no command), so opening I/O does not change the servo state.
  :meth:`CyclicIo.enable` / :meth:`CyclicIo.disable` send a new command at once: a frame
  with the no-command word, then the command, each with a new 16-bit sequence count, so
  every call is an edge the drive acts on (like writing instance 0x0D), also after the
  servo state was changed another way;
* input frames are taken only from the adapter's address, for the T->O connection id, with
  a newer 32-bit sequence number; gaps count as ``missed``, older or repeated frames as
  ``stale``. Each frame keeps its arrival time (``time.monotonic()``) and, on Linux, the
  kernel's receive time (``wire_time``, ``udp.py``).

Loss detection and reconnect (decisions): the connection is lost when no input frame came
for the watchdog time, T->O RPI x 4 x 2^``multiplier`` (CIP's connection timeout;
``multiplier`` defaults to 2, 16 RPIs, so a scheduling hiccup of the host does not make the
drive brake and disable on its own fieldbus-loss watchdog). The adapter then runs its
fieldbus-loss action (it brakes and disables the servo: docs/enip.md). With
``reconnect=True`` (default) the scanner then Forward_Closes the old connection (best
effort), re-registers the explicit session if it died, and Forward_Opens again with a new
connection serial number every ``max(watchdog, 0.1 s)`` until it succeeds or the I/O is
closed; frame iterators just wait meanwhile. With ``reconnect=False`` iterators raise
ConnectionLost. The originator vendor id is 0x5342 ("SB"; servobus has no ODVA id), the
originator serial number is random per process.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import random
import socket
import threading
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import asdict, dataclass
from typing import Protocol, cast

from servobus import checks
from servobus.axis.types import AxisStatus
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
    FramingError,
    ProtocolError,
)
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.family import axis_status
from servobus.protocols.enip.client import AsyncEnipClient
from servobus.protocols.enip.clock import ClockThread, Tick
from servobus.protocols.enip.codec import io
from servobus.protocols.enip.codec.cip import GeneralStatus, MessageRouterRequest, Service
from servobus.protocols.enip.codec.connection_manager import (
    CONNECTION_MANAGER_PATH,
    TIMEOUT_MULTIPLIER_MAX,
    ExtendedStatus,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    Triad,
    watchdog_s,
)
from servobus.protocols.enip.codec.cpf import ItemType, SockaddrInfo
from servobus.protocols.enip.codec.epath import LogicalType, Segment, logical
from servobus.protocols.enip.production import Producer, ProductionWheel
from servobus.protocols.enip.udp import UdpSocket


class Session(Protocol):
    """What the I/O needs of the axis that opens it (``EnipAxis``): the adapter's address and
    its explicit session, reconnected after a loss (typed here: the axis imports this)."""

    ip: str

    async def client(self, connect_timeout: float | None = None) -> AsyncEnipClient: ...
    async def reconnect(self) -> None: ...

log = logging.getLogger("servobus.enip")

ORIGINATOR_VENDOR = 0x5342
ORIGINATOR_SERIAL = random.getrandbits(32)
DEFAULT_MULTIPLIER = 2
DEFAULT_QUEUE = 1024
MIN_RECONNECT_S = 0.1
NO_COMMAND = 0
#: Config instance 0, consumed point 101, produced point 100 (the Rockwell generic form).
CONNECTION_PATH: tuple[Segment, ...] = (
    logical(LogicalType.CLASS, 0x04), logical(LogicalType.INSTANCE, dyn5.CONFIG_ASSEMBLY),
    logical(LogicalType.CONNECTION_POINT, dyn5.OUTPUT_ASSEMBLY),
    logical(LogicalType.CONNECTION_POINT, dyn5.INPUT_ASSEMBLY))
_serials = itertools.count(random.getrandbits(16))


@dataclass(frozen=True)
class InputFrame:
    """One T->O frame: arrival time in this process and at the socket (``time.monotonic()``
    base, s; ``udp.py``), 32-bit sequence number, 16-bit sequence count and the input image
    (position counts, speed rpm, torque 2000 = peak, status)."""

    time: float
    sequence: int
    count: int
    image: io.InputImage
    wire_time: float = 0.0  # when the network delivered it (kernel stamp, udp.py); = time

    @property
    def position(self) -> int:
        return self.image.position

    @property
    def speed(self) -> int:
        return self.image.speed

    @property
    def torque(self) -> int:
        return self.image.torque

    @property
    def status(self) -> AxisStatus:
        return axis_status(self.image.status, self.image.speed)

    def as_dict(self) -> dict[str, object]:
        return {"time": self.time, "wire_time": self.wire_time, "sequence": self.sequence,
                "count": self.count,
                "position": self.position, "speed": self.speed, "torque": self.torque,
                "status": self.image.status}


@dataclass
class IoStats:
    frames: int = 0  # input frames taken
    missed: int = 0  # sequence-number gaps (frames the network or the host lost)
    stale: int = 0  # older or repeated sequence numbers
    foreign: int = 0  # malformed, another connection id or another sender
    sent: int = 0  # output frames sent
    losses: int = 0  # watchdog expiries
    reconnects: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class FrameStream:
    """An async iterator over input frames from the moment it was made (bounded: when the
    consumer falls behind, the oldest frames go and ``dropped`` counts them)."""

    def __init__(self, owner: CyclicIo, maxlen: int, timeout: float | None) -> None:
        self._owner = owner
        self._frames: deque[InputFrame] = deque()
        self._maxlen = maxlen
        self._timeout = timeout
        self._waiter: asyncio.Future[None] | None = None
        self._end: BaseException | None = None
        self._done = False
        self.dropped = 0

    def push(self, frame: InputFrame) -> None:
        if len(self._frames) >= self._maxlen:
            self._frames.popleft()
            self.dropped += 1
        self._frames.append(frame)
        self._wake()

    def finish(self, error: BaseException | None = None) -> None:
        self._done = True
        self._end = error
        self._wake()

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def __aiter__(self) -> FrameStream:
        return self

    async def __anext__(self) -> InputFrame:
        while not self._frames:
            if self._done:
                self._owner.forget(self)
                if self._end is not None:
                    raise self._end
                raise StopAsyncIteration
            loop = asyncio.get_running_loop()
            self._waiter = waiter = loop.create_future()
            try:
                if self._timeout is None:
                    await waiter
                else:
                    await asyncio.wait_for(waiter, self._timeout)
            except TimeoutError:
                raise DriveTimeout(f"no input frame within {self._timeout:g} s") from None
            finally:
                self._waiter = None
        return self._frames.popleft()

    async def aclose(self) -> None:
        self._done = True
        self._owner.forget(self)


def local_address_for(ip: str) -> str:
    """The local IPv4 address the host routes ``ip`` through (no packet is sent)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect((ip, io.UDP_PORT))
        return str(probe.getsockname()[0])


class CyclicIo:
    """Class 1 I/O with one DYN5 (module docstring). Use ``async with axis.io(...)``."""

    def __init__(self, axis: Session, *, rpi_ms: float = 10.0,
                 multiplier: int = DEFAULT_MULTIPLIER, reconnect: bool = True,
                 queue: int = DEFAULT_QUEUE,
                 on_frame: Callable[[InputFrame], None] | None = None,
                 clock: str = "thread") -> None:
        """``on_frame`` (optional) is called with each input frame as it arrives, on the
        event loop, before the frame iterators see it: the low-latency path (keep it short).
        ``clock``: ``"thread"`` (default) sends the O->T frames from servobus's clock thread
        (absolute deadlines, SCHED_FIFO where permitted: ``clock.py``); ``"loop"`` from the
        event loop's timer (``production.py``), as before issue 22 - also where the UDP
        socket is an asyncio transport that only its loop may use (no ``add_reader``)."""
        if clock not in ("thread", "loop"):
            raise ArgumentRangeError(f"clock must be 'thread' or 'loop', got {clock!r}")
        self.clock = clock
        rpi_s = checks.seconds("rpi_ms", rpi_ms) / 1e3
        self.rpi_us = round(rpi_s * 1e6)
        if self.rpi_us < dyn5.MIN_RPI_US:
            raise ArgumentRangeError(f"rpi_ms={rpi_ms!r}: the DYN5's minimum RPI is "
                                     f"{dyn5.MIN_RPI_US / 1e3:g} ms (manual 7)")
        if isinstance(multiplier, bool) or not isinstance(multiplier, int) or not (
                0 <= multiplier <= TIMEOUT_MULTIPLIER_MAX):
            raise ArgumentRangeError(f"multiplier must be 0..{TIMEOUT_MULTIPLIER_MAX}, "
                                     f"got {multiplier!r}")
        self.axis = axis
        self.multiplier = multiplier
        self.reconnect = bool(reconnect)
        self.queue = checks.positive_int("queue", queue)
        if on_frame is not None and not callable(on_frame):
            raise ArgumentRangeError(f"on_frame must be callable, got {on_frame!r}")
        self.on_frame = on_frame
        self.stats = IoStats()
        self.latest: InputFrame | None = None
        self.watchdog_s = watchdog_s(self.rpi_us, multiplier)
        self.api_us = (self.rpi_us, self.rpi_us)  # O->T, T->O as the adapter granted them
        self._loop: asyncio.AbstractEventLoop | None = None
        self._udp: UdpSocket | None = None
        self._local: tuple[str, int] = ("", 0)
        self._triad: Triad | None = None
        self._o_t_id = 0
        self._t_o_id = 0
        self._o_t_dest: tuple[str, int] = (axis.ip, io.UDP_PORT)
        self._packer: io.FramePacker | None = None
        self._sequence = 0
        self._count = 0
        self._word = NO_COMMAND
        self._last_seq: int | None = None
        self._last_rx = 0.0
        self._tick: Producer | Tick | None = None
        self._producing = False  # O->T frames may leave (guarded by _send_lock)
        self._send_lock = threading.Lock()  # _send runs on the clock thread too
        self._watch: asyncio.TimerHandle | None = None
        self._reconnecting: asyncio.Task[None] | None = None
        self._streams: set[FrameStream] = set()
        self._connected = False
        self._closed = False

    # ---------------------------------------------------------------- lifecycle
    async def __aenter__(self) -> CyclicIo:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def rpi_s(self) -> float:
        return self.api_us[1] / 1e6

    async def open(self) -> None:
        """UDP socket, Forward_Open, O->T production; raises DriveError when refused."""
        self._loop = asyncio.get_running_loop()
        await self.axis.client()
        local_ip = local_address_for(self.axis.ip)
        self._udp = await UdpSocket.open((local_ip, 0), self._datagram)
        self._local = self._udp.sockname
        try:
            await self._forward_open()
        except BaseException:
            self._udp.close()
            self._closed = True
            raise

    async def close(self) -> None:
        """Stop producing, Forward_Close (best effort), close the socket; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stop_timers()
        task, self._reconnecting = self._reconnecting, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if self._connected:
            self._connected = False
            with contextlib.suppress(DriveTimeout, ConnectionLost, ProtocolError, DriveError):
                await self._forward_close()
        if self._udp is not None:
            self._udp.close()
        for stream in list(self._streams):
            stream.finish()

    def _stop_timers(self) -> None:
        with self._send_lock:
            self._producing = False
        if isinstance(self._tick, Tick):
            ClockThread.shared().remove(self._tick)
        elif self._tick is not None and self._loop is not None:
            ProductionWheel.for_loop(self._loop).remove(self._tick)
        if self._watch is not None:
            self._watch.cancel()
        self._tick = None
        self._watch = None

    # ---------------------------------------------------------------- Connection Manager
    async def _forward_open(self) -> None:
        client = await self.axis.client()
        triad = Triad(next(_serials) & 0xFFFF, ORIGINATOR_VENDOR, ORIGINATOR_SERIAL)
        t_o_id = random.getrandbits(32) or 1
        request = ForwardOpenRequest(
            0, t_o_id, triad, self.rpi_us, NetworkParameters(io.O_T_CONNECTION_SIZE).to_word(),
            self.rpi_us, NetworkParameters(io.T_O_CONNECTION_SIZE).to_word(),
            TransportTrigger().to_byte(), CONNECTION_PATH, timeout_multiplier=self.multiplier)
        message = MessageRouterRequest(Service.FORWARD_OPEN, CONNECTION_MANAGER_PATH,
                                       request.encode()).encode()
        sockaddr = SockaddrInfo(self._local[1], self._local[0]).item(ItemType.SOCKADDR_T_O)
        self._t_o_id = t_o_id  # point-to-point: the consumer's id stands; the first frame
        self._last_seq = None  # may come before the reply is read
        try:
            response, items = await client.request(message, read=False, extra=(sockaddr,))
        except BaseException:
            self._t_o_id = 0
            raise
        if not response.ok:
            self._t_o_id = 0
            status = (response.general_status, response.additional_status)
            raise DriveError(f"{self.axis.ip} refused Forward_Open: "
                             f"{_connection_status(*status)}", code=_extended(*status))
        reply = ForwardOpenReply.decode(response.data)
        o_t = items.sockaddr_o_t
        if o_t is not None:
            ip = o_t.address if o_t.address != "0.0.0.0" else self.axis.ip
            self._o_t_dest = (ip, o_t.port)
        else:
            self._o_t_dest = (self.axis.ip, io.UDP_PORT)
        self._triad = triad
        self._o_t_id = reply.o_t_connection_id
        if reply.t_o_connection_id != t_o_id:
            self._t_o_id = reply.t_o_connection_id
            self._last_seq = None
        self.api_us = (reply.o_t_api_us or self.rpi_us, reply.t_o_api_us or self.rpi_us)
        self.watchdog_s = watchdog_s(self.api_us[1], self.multiplier)
        self._packer = io.output_packer(self._o_t_id)
        self._connected = True
        assert self._loop is not None
        now = self._loop.time()
        self._last_rx = now
        with self._send_lock:
            self._producing = True
        if self.clock == "thread" and self._udp is not None and self._udp.threadsafe_send:
            self._tick = ClockThread.shared().add(self.api_us[0] / 1e6, self._send)
        else:
            self._tick = ProductionWheel.for_loop(self._loop).add(
                Producer(self.api_us[0] / 1e6, now, self._send))
        self._watch = self._loop.call_at(now + self.watchdog_s, self._check_watchdog)
        log.info("Class 1 I/O with %s open: O->T 0x%08X to %s:%d, T->O 0x%08X to %s:%d, "
                 "RPI %.1f ms", self.axis.ip, self._o_t_id, *self._o_t_dest, self._t_o_id,
                 *self._local, self.api_us[1] / 1e3)

    async def _forward_close(self) -> None:
        if self._triad is None:
            return
        client = await self.axis.client()
        request = ForwardCloseRequest(self._triad, CONNECTION_PATH)
        message = MessageRouterRequest(Service.FORWARD_CLOSE, CONNECTION_MANAGER_PATH,
                                       request.encode()).encode()
        triad, self._triad = self._triad, None
        response, _ = await client.request(message, read=False)
        if not response.ok:
            log.info("Forward_Close of serial 0x%04X: %s", triad.connection_serial,
                     _connection_status(response.general_status, response.additional_status))

    # ---------------------------------------------------------------- O->T
    def _send(self) -> None:
        """One O->T frame: on the clock thread (each period) or the loop (a new word)."""
        with self._send_lock:
            if (self._udp is None or self._packer is None or not self._connected
                    or not self._producing):
                return
            self._sequence = (self._sequence + 1) & 0xFFFF_FFFF
            frame = self._packer.pack(self._sequence, self._count, io.RUN_BIT, self._word)
            self._udp.sendto(frame, self._o_t_dest)
            self.stats.sent += 1

    def _new_data(self, word: int) -> None:
        with self._send_lock:
            self._word = word
            self._count = (self._count + 1) & 0xFFFF
        self._send()

    async def set_output(self, word: int) -> None:
        """Send ``word`` (0xAAAA enable, 0xDEDE disable, anything else: no command) now, as
        a new command (an edge, module docstring); it stays the output image."""
        if isinstance(word, bool) or not isinstance(word, int) or not 0 <= word <= 0xFFFF_FFFF:
            raise ArgumentRangeError(f"the output word is a UDINT, got {word!r}")
        if not self._connected:
            raise ConnectionLost(f"I/O with {self.axis.ip} is not connected")
        self._new_data(NO_COMMAND)
        self._new_data(word)

    async def enable(self, *, wait: bool = False, timeout: float = 1.0) -> None:
        """0xAAAA through the output image; ``wait``: until an input frame shows it enabled."""
        await self.set_output(dyn5.ENABLE)
        if wait:
            await self.wait_status(lambda st: st.enabled, timeout, "enabled")

    async def disable(self, *, wait: bool = False, timeout: float = 1.0) -> None:
        await self.set_output(dyn5.DISABLE)
        if wait:
            await self.wait_status(lambda st: not st.enabled, timeout, "disabled")

    async def wait_status(self, predicate: Callable[[AxisStatus], bool], timeout: float = 1.0,
                          what: str = "status") -> InputFrame:
        """The first input frame from now whose status satisfies ``predicate``."""
        limit = checks.seconds("timeout", timeout)
        try:
            async with asyncio.timeout(limit):
                async for frame in self.frames():
                    if predicate(frame.status):
                        return frame
        except TimeoutError:
            pass
        raise DriveTimeout(f"input frames of {self.axis.ip} did not show {what} within "
                           f"{limit:g} s")

    # ---------------------------------------------------------------- T->O
    def frames(self, *, timeout: float | None = None) -> AsyncIterator[InputFrame]:
        """Input frames from now on; ``timeout``: DriveTimeout when none comes that long."""
        if timeout is not None:
            checks.seconds("timeout", timeout)
        stream = FrameStream(self, self.queue, timeout)
        if self._closed:
            stream.finish()
        else:
            self._streams.add(stream)
        return stream

    def forget(self, stream: FrameStream) -> None:
        self._streams.discard(stream)

    async def next_frame(self, timeout: float = 1.0) -> InputFrame:
        stream = self.frames(timeout=timeout)
        try:
            return await stream.__anext__()
        finally:
            self.forget(cast(FrameStream, stream))

    def _datagram(self, data: bytes, addr: tuple[str, int], now: float, wire: float) -> None:
        try:
            conn, seq, count, image = io.unpack_input(data)
        except FramingError:
            self.stats.foreign += 1
            return
        if conn != self._t_o_id or not conn or addr[0] != self.axis.ip or self._closed:
            self.stats.foreign += 1
            return
        last = self._last_seq
        if last is not None:
            if not io.seq32_newer(seq, last):
                self.stats.stale += 1
                return
            self.stats.missed += (seq - last - 1) & 0xFFFF_FFFF
        self._last_seq = seq
        self._last_rx = now
        frame = InputFrame(now, seq, count, image, wire)
        self.latest = frame
        self.stats.frames += 1
        if self.on_frame is not None:
            self.on_frame(frame)
        for stream in self._streams:
            stream.push(frame)

    # ---------------------------------------------------------------- loss and reconnect
    def _check_watchdog(self) -> None:
        loop = self._loop
        assert loop is not None
        self._watch = None
        due = self._last_rx + self.watchdog_s
        if loop.time() < due:
            self._watch = loop.call_at(due, self._check_watchdog)
            return
        self.stats.losses += 1
        self._connected = False
        self._t_o_id = 0
        self._stop_timers()
        log.warning("Class 1 I/O with %s lost: no input frame for %.0f ms", self.axis.ip,
                    self.watchdog_s * 1e3)
        if self.reconnect and not self._closed:
            self._reconnecting = loop.create_task(self._reconnect())
            return
        error = ConnectionLost(f"I/O with {self.axis.ip} lost: no input frame for "
                               f"{self.watchdog_s * 1e3:.0f} ms")
        for stream in list(self._streams):
            stream.finish(error)

    async def _reconnect(self) -> None:
        delay = max(self.watchdog_s, MIN_RECONNECT_S)
        while not self._closed:
            try:
                client = await self.axis.client()
                if client.closed:
                    await self.axis.reconnect()
                else:
                    with contextlib.suppress(DriveTimeout, DriveError, ProtocolError):
                        await self._forward_close()
                await self._forward_open()
                self.stats.reconnects += 1
                log.info("Class 1 I/O with %s reconnected", self.axis.ip)
                return
            except (DriveTimeout, ConnectionLost, DriveError, ProtocolError) as exc:
                log.info("I/O reconnect to %s failed: %s", self.axis.ip, exc)
            await asyncio.sleep(delay)


def _extended(general: int, additional: tuple[int, ...]) -> int:
    return additional[0] if general == GeneralStatus.CONNECTION_FAILURE and additional else general


def _connection_status(general: int, additional: tuple[int, ...]) -> str:
    if general == GeneralStatus.CONNECTION_FAILURE and additional:
        code = additional[0]
        try:
            name = ExtendedStatus(code).name.lower().replace("_", " ")
        except ValueError:
            name = "extended status"
        return f"{name} (0x{code:04X})"
    return f"CIP status 0x{general:02X}"
