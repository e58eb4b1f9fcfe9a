"""CAN frames for asyncio over any python-can bus, plus a CAN bit-timing model.

``open_can("INTERFACE:CHANNEL", **kwargs)`` opens ``can.Bus(interface=..., channel=...,
**kwargs)`` exactly as python-can users write it ("pcan:PCAN_USBBUS1", "socketcan:can0",
"slcan:/dev/ttyACM0", "virtual:bus0"). For socketcand the channel part is "HOST:PORT"
(the daemon's address) and the CAN channel served there defaults to "can0" (override
with ``channel=``). Frames are received through python-can's own ``can.Notifier`` running
its listeners on the event loop - except on python-can's ``virtual`` bus, where the
senders' ``put`` wakes the loop directly (:class:`_LoopQueue`, docs/performance.md);
sending calls ``bus.send`` directly (every python-can backend's send returns quickly: it
queues the frame in the adapter or the socket).

Transports move frames only: this module knows nothing about DYN CAN function codes.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import os
import queue
import socket
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from servobus.errors import ArgumentRangeError, ConnectionLost
from servobus.transport.base import Direction

SOCKETCAND_DEFAULT_CHANNEL = "can0"
NOTIFIER_POLL_S = 0.1  # python-can Notifier recv timeout: bounds close() latency
#: How long opening a socketcand bus waits for the daemon to accept and greet (issue 29).
SOCKETCAND_CONNECT_S = 5.0


@dataclass(frozen=True)
class CanFrame:
    """A CAN data frame as the transport moves it (11- or 29-bit identifier)."""

    arbitration_id: int
    data: bytes
    timestamp: float = 0.0
    is_extended_id: bool = False
    #: The time.monotonic() instant the frame reached the bus, where the medium knows it
    #: (the socketcand hub stamps frames as their TCP data arrives); None: unknown.
    arrived: float | None = None


#: Called with every frame moved (TX or RX) and the monotonic time it moved.
FrameTraceHook = Callable[[Direction, CanFrame, float], None]


@runtime_checkable
class FramePort(Protocol):
    """What clients and virtual nodes need from a CAN medium (one event loop)."""

    async def send(self, arbitration_id: int, data: bytes) -> None:
        """Put one base-format data frame on the bus."""

    async def recv(self, timeout: float | None = None) -> CanFrame | None:
        """Next frame from the bus, or None when ``timeout`` passes.

        Raises :class:`~servobus.errors.ConnectionLost` when the port is closed or failed
        (``send`` too).
        """

    def add_trace(self, hook: FrameTraceHook) -> None:
        """Call ``hook`` for every frame sent (TX) or received (RX)."""

    async def close(self) -> None:
        """Release the medium; idempotent."""


#: Push-style reception (optional on a FramePort): frames, then None when the port closes.
FrameReceiver = Callable[["CanFrame | None"], None]


def set_receiver(port: FramePort, receiver: FrameReceiver) -> bool:
    """Ask ``port`` to push frames to ``receiver`` on the loop instead of queueing them.

    Saves one task switch per frame (the client's receive path); ports without the
    capability return False and the caller keeps calling ``recv``.
    """
    method = getattr(port, "set_receiver", None)
    if method is None:
        return False
    method(receiver)
    return True


# ------------------------------------------------------------------ bit timing
@dataclass(frozen=True)
class BitTiming:
    """CAN 2.0A frame duration model.

    A base data frame has 47 fixed bits + 8 per data byte (SOF, 11-bit id, RTR, IDE, r0,
    DLC 4, CRC 15, CRC delimiter, ACK 2, EOF 7, intermission 3). Bit stuffing applies to
    the 34 + 8n bits from SOF to the CRC; servobus estimates it with the worst case, one
    stuff bit per 4 bits after the first ((34 + 8n - 1) // 4), so the model never promises
    more bus capacity than a real bus has.
    """

    bitrate: int = 1_000_000

    def frame_bits(self, dlc: int) -> int:
        stuffed_region = 34 + 8 * dlc
        return 47 + 8 * dlc + (stuffed_region - 1) // 4

    def frame_time(self, dlc: int) -> float:
        return self.frame_bits(dlc) / self.bitrate


class BusPacer:
    """Keeps a model of when the bus is free; delays sends so throughput matches the model.

    asyncio sleeps are only millisecond-accurate, so the pacer lets short debts accumulate
    and sleeps once the modelled bus runs more than ``slack`` ahead of the wall clock:
    throughput and queueing follow the model, single-frame latency is within ``slack``.
    """

    def __init__(self, timing: BitTiming, slack: float = 0.001) -> None:
        self.timing = timing
        self.slack = slack
        self.free_at = 0.0
        self.busy_s = 0.0  # total modelled bus time, for load figures
        self.frames = 0

    def occupy(self, dlc: int, start: float | None = None) -> float:
        """Account one frame starting no earlier than ``start``; returns its end time."""
        now = time.monotonic() if start is None else start
        t = self.timing.frame_time(dlc)
        self.free_at = max(self.free_at, now) + t
        self.busy_s += t
        self.frames += 1
        return self.free_at

    async def wait_sent(self, dlc: int) -> None:
        end = self.occupy(dlc)
        ahead = end - time.monotonic()
        if ahead > self.slack:
            await asyncio.sleep(ahead)


# ------------------------------------------------------------------ opening buses
def parse_can_spec(spec: str, **options: Any) -> dict[str, Any]:
    """"INTERFACE:CHANNEL" -> keyword arguments for ``can.Bus``.

    socketcand: "socketcand:HOST:PORT" -> host, port, channel (default "can0").
    """
    interface, sep, rest = spec.partition(":")
    if not sep or not interface:
        raise ArgumentRangeError(
            f"CAN bus {spec!r} must be INTERFACE:CHANNEL, e.g. 'pcan:PCAN_USBBUS1', "
            "'virtual:bus0' or 'socketcand:127.0.0.1:29536'"
        )
    kwargs: dict[str, Any] = dict(options)
    kwargs["interface"] = interface
    if interface == "socketcand":
        host, sep, port = rest.rpartition(":")
        if not sep or not host or not port.isdigit():
            raise ArgumentRangeError(f"socketcand address {rest!r} must be HOST:PORT")
        kwargs["host"] = host
        kwargs["port"] = int(port)
        kwargs.setdefault("channel", SOCKETCAND_DEFAULT_CHANNEL)
    else:
        kwargs["channel"] = rest
    return kwargs


def open_bus(spec: str, **options: Any) -> Any:
    """Blocking: ``can.Bus(**parse_can_spec(spec, **options))``.

    socketcand: the daemon is tried once first (:func:`_reach_socketcand`). A bus python-can
    cannot open (no such interface or channel, a missing driver library, the OS without
    CAN sockets) is a ConnectionLost naming it (decision: a CAN adapter plugged in later may
    open then, as a serial port may; python-can's own errors are not servobus's types)."""
    import can  # lazy: python-can is only needed for CAN work

    kwargs = parse_can_spec(spec, **options)
    if kwargs["interface"] == "socketcand":
        _reach_socketcand(kwargs["host"], kwargs["port"])
    try:
        return can.Bus(**kwargs)
    except (OSError, can.CanError) as exc:
        raise ConnectionLost(f"cannot open CAN bus {spec}: {exc}") from exc


def _reach_socketcand(host: str, port: int, timeout: float | None = None) -> None:
    """ConnectionLost within ``timeout`` (default :data:`SOCKETCAND_CONNECT_S`) when nothing
    at ``host:port`` greets as a socketcand daemon does (``< hi >`` on connect).

    Decision (issue 29): python-can's socketcand client retries ``connect`` in a tight loop
    for 10 s, logging one warning per try (~255,000 lines), and then raises a bare
    TimeoutError; and once connected it waits for the greeting with no timeout at all, so a
    peer that accepts and says nothing (a hung daemon, another service on that port) held
    ``connect()`` for ever. One plain connection first, waiting for the greeting, turns both
    into one typed error within the connect timeout; the daemon sees a client that hangs up
    before ``open``. A daemon that goes away between this try and python-can's own is the
    narrow case left to python-can."""
    greeting = b"< hi >"
    timeout = SOCKETCAND_CONNECT_S if timeout is None else timeout
    deadline = time.monotonic() + timeout
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            heard = b""
            while greeting not in heard:
                sock.settimeout(max(deadline - time.monotonic(), 0.001))
                data = sock.recv(64)
                if not data:
                    raise ConnectionLost(f"cannot reach socketcand at {host}:{port}: it "
                                         "closed the connection before its greeting")
                heard = (heard + data)[-64:]
    except TimeoutError as exc:
        raise ConnectionLost(f"cannot reach socketcand at {host}:{port}: no greeting within "
                             f"{timeout:g} s") from exc
    except OSError as exc:
        raise ConnectionLost(f"cannot reach socketcand at {host}:{port}: "
                             f"{exc.strerror or exc}") from exc


def _watch_socketcand_eof(bus: Any, on_eof: Callable[[BaseException], object]) -> None:
    """Make python-can's socketcand client notice that the daemon hung up.

    Its receive loop reads ``b""`` from a closed socket as "no frame yet" and spins: a read
    waiting for a reply would only fail at its deadline, sends fail later still. When its
    ``_recv_internal`` returns no frame, a non-blocking ``MSG_PEEK`` tells an idle socket
    (would block) from a closed one (``b""``); then ``on_eof`` is called once (from the
    Notifier thread) and the receive loop idles instead of spinning. Uses python-can's
    private socket attribute; without it (another version) nothing changes.
    """
    sock = getattr(bus, "_SocketCanDaemonBus__socket", None)
    inner = getattr(bus, "_recv_internal", None)
    if not isinstance(sock, socket.socket) or inner is None:
        return
    ended: list[BaseException] = []

    def recv_internal(timeout: float | None) -> Any:
        if ended:
            time.sleep(NOTIFIER_POLL_S if timeout is None else min(timeout, NOTIFIER_POLL_S))
            return None, False
        try:
            result = inner(timeout)
            if result[0] is not None:
                return result
            if sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) != b"":
                return result
            error: BaseException = ConnectionLost("socketcand closed the connection")
        except BlockingIOError:
            return None, False
        except Exception as exc:  # the socket is gone, or python-can's CanError
            error = exc
        ended.append(error)
        on_eof(error)
        return None, False

    bus._recv_internal = recv_internal


class _QueueListener:
    """python-can listener (duck-typed) feeding an asyncio queue on the loop thread."""

    def __init__(self, port: AsyncCanBus) -> None:
        self._port = port

    def __call__(self, msg: Any) -> None:  # Notifier calls listeners on the loop thread
        self._port._deliver(msg)

    def on_error(self, exc: Exception) -> None:
        self._port._fail(exc)

    def stop(self) -> None:
        pass


class _BatchingListener:
    """python-can listener (duck-typed) called on the Notifier's thread: frames are queued
    and the loop is woken once per burst, not once per frame.

    For buses the Notifier serves from a thread (socketcand: no file descriptor to watch
    on the loop): with ``loop=`` python-can calls ``call_soon_threadsafe`` for every frame,
    a self-pipe write and an event-loop wake each - with 16 drives answering at 50 Hz that
    was a large share of the gateway's CPU. An error still ends the Notifier's thread, as
    it does with ``loop=``.
    """

    def __init__(self, port: AsyncCanBus) -> None:
        self._port = port
        self._frames: collections.deque[Any] = collections.deque()
        self._woken = False

    def __call__(self, msg: Any) -> None:
        self._frames.append(msg)
        if not self._woken:
            self._woken = True
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                self._port._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        self._woken = False  # before reading: a frame appended from now on wakes again
        frames = self._frames
        while frames:
            self._port._deliver(frames.popleft())

    def on_error(self, exc: Exception) -> None:
        self._port._fail_threadsafe(exc)
        raise NotImplementedError  # "not handled": the Notifier's thread ends, as with loop=

    def stop(self) -> None:
        pass


class _LoopQueue(queue.Queue[Any]):
    """The receive queue of one python-can ``virtual`` bus, pushing to the loop directly.

    python-can's virtual bus hands a sent frame to every other bus on the channel with
    ``queue.put``; with a Notifier a thread of ours would block in ``get``, wake per frame
    and wake the loop in turn. Put in the bus's place, this queue wakes the loop itself
    from the sender's thread, once per burst: one thread hand-off less per frame. The wake
    is an eventfd the loop watches (Linux; elsewhere ``call_soon_threadsafe``, whose
    self-pipe costs a socket send and receive per wake), and ``call_soon`` when the sender
    is the loop's own thread (a client and a virtual drive on one loop): no system call.
    Same capacity as the queue it replaces.
    """

    def __init__(self, maxsize: int, loop: asyncio.AbstractEventLoop,
                 deliver: Callable[[Any], None]) -> None:
        super().__init__(maxsize)
        self._loop = loop
        self._loop_thread = threading.get_ident()
        self._deliver = deliver
        self._woken = False
        self.replaced: queue.Queue[Any] | None = None  # the bus's own queue, taken over
        self._efd = -1
        if hasattr(os, "eventfd"):
            efd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
            self._release = weakref.finalize(self, os.close, efd)  # once, even if leaked
            try:
                loop.add_reader(efd, self._on_wake)
                self._efd = efd
            except (NotImplementedError, RuntimeError):  # a loop without fd watching
                self._release()

    def _put(self, item: Any) -> None:  # called by put() under the queue's mutex
        super()._put(item)
        if self._woken:
            return
        self._woken = True
        if threading.get_ident() == self._loop_thread:
            self._loop.call_soon(self._drain)
        elif self._efd >= 0:
            # try, not contextlib.suppress: this is every frame's path
            try:  # noqa: SIM105
                os.eventfd_write(self._efd, 1)
            except OSError:  # closed: nobody listens any more
                pass
        else:
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                self._loop.call_soon_threadsafe(self._drain)

    def _on_wake(self) -> None:
        try:  # noqa: SIM105  (as in _put)
            os.eventfd_read(self._efd)
        except BlockingIOError:  # a drain already took what woke it
            pass
        self._drain()

    def _drain(self) -> None:
        self._woken = False  # before taking: a frame put from now on wakes again
        with self.mutex:  # the whole burst at once (get_nowait per frame costs twice)
            msgs = list(self.queue)
            self.queue.clear()
            if msgs and self.maxsize > 0:
                self.not_full.notify_all()
        for msg in msgs:
            self._deliver(msg)

    def close(self) -> None:
        """Stop watching the eventfd and close it (on the loop's thread); idempotent."""
        efd, self._efd = self._efd, -1
        self._woken = True  # frames put from now on wake nobody
        if efd >= 0:
            with contextlib.suppress(RuntimeError, ValueError, OSError):
                self._loop.remove_reader(efd)
            self._release()


def _take_virtual_queue(bus: Any, port: AsyncCanBus) -> _LoopQueue | None:
    """Put a :class:`_LoopQueue` in place of a python-can ``virtual`` bus's receive queue
    (``replaced`` keeps the old one, given back on close when the port does not own the bus).

    Uses the bus's ``queue`` and ``channel`` attributes (python-can 4); on another shape
    nothing changes (None) and the caller runs a Notifier as for any bus.
    """
    try:
        from can.interfaces import virtual
    except ImportError:
        return None
    if type(bus) is not virtual.VirtualBus:
        return None
    old = getattr(bus, "queue", None)
    if not isinstance(old, queue.Queue) or not isinstance(getattr(bus, "channel", None), list):
        return None
    new = _LoopQueue(old.maxsize, port._loop, port._deliver)
    new.replaced = old
    if not _swap_queue(bus, old, new):
        new.close()
        return None
    return new


def _swap_queue(bus: Any, old: queue.Queue[Any], new: queue.Queue[Any]) -> bool:
    """Put ``new`` where ``old`` receives on a virtual bus's channel, with the frames that
    wait in ``old`` (up to ``new``'s capacity); False if ``old`` no longer receives there."""
    from can.interfaces import virtual

    with virtual.channels_lock:
        channel = bus.channel
        if not any(q is old for q in channel):
            return False
        channel[:] = [new if q is old else q for q in channel]
        bus.queue = new
    with contextlib.suppress(queue.Empty, queue.Full):
        while True:
            new.put_nowait(old.get_nowait())
    return True


def _threaded(bus: Any) -> bool:
    """Whether python-can's Notifier would serve ``bus`` from a thread even with a loop."""
    try:
        return bool(bus.fileno() < 0)
    except (NotImplementedError, AttributeError, OSError, ValueError):
        return True


class AsyncCanBus:
    """A python-can bus as a :class:`FramePort`.

    ``timing`` (a BitTiming) turns on the bus-time model for the simulator side: frames
    received occupy the modelled bus, and each send waits for its slot.
    """

    def __init__(self, bus: Any, *, timing: BitTiming | None = None, owns_bus: bool = True
                 ) -> None:
        import can

        self._can = can
        self.bus = bus
        self._owns_bus = owns_bus
        self._queue: asyncio.Queue[CanFrame | BaseException] = asyncio.Queue()
        self._traces: list[FrameTraceHook] = []
        self._closed = False
        self._failure: ConnectionLost | None = None
        self._receiver: FrameReceiver | None = None
        self.pacer = BusPacer(timing) if timing is not None else None
        self._loop = loop = asyncio.get_running_loop()
        self._notifier: Any = None
        # python-can's virtual bus: frames come straight from the senders' put, no thread
        self._direct = _take_virtual_queue(bus, self)
        if self._direct is not None:
            pass
        elif _threaded(bus):
            self._notifier = can.Notifier(bus, [_BatchingListener(self)],
                                          timeout=NOTIFIER_POLL_S)
        else:
            self._notifier = can.Notifier(bus, [_QueueListener(self)],
                                          timeout=NOTIFIER_POLL_S, loop=loop)
        _watch_socketcand_eof(bus, self._fail_threadsafe)

    @classmethod
    async def open(cls, spec: str, *, timing: BitTiming | None = None, **options: Any
                   ) -> AsyncCanBus:
        """Open ``spec`` without blocking the loop (socketcand connects over TCP)."""
        bus = await asyncio.to_thread(open_bus, spec, **options)
        return cls(bus, timing=timing)

    # -------------------------------------------------------------- receive side
    def _deliver(self, msg: Any) -> None:
        if self._closed or msg.is_error_frame or msg.is_remote_frame:
            return
        frame = CanFrame(msg.arbitration_id, bytes(msg.data), msg.timestamp,
                         msg.is_extended_id)
        if self.pacer is not None or self._traces:
            now = time.monotonic()
            if self.pacer is not None:
                self.pacer.occupy(len(frame.data), now)
            for hook in self._traces:
                hook(Direction.RX, frame, now)
        if self._receiver is not None:
            self._receiver(frame)
        else:
            self._queue.put_nowait(frame)

    def _fail_threadsafe(self, exc: BaseException) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is already closed
            self._loop.call_soon_threadsafe(self._fail, exc)

    def _fail(self, exc: BaseException) -> None:
        """The bus broke (python-can's Notifier met an error receiving): every later call
        raises ConnectionLost, and a receiver or a waiting ``recv`` hears of it at once."""
        if self._failure is not None or self._closed:
            return
        self._failure = ConnectionLost(f"CAN bus failed: {exc}")
        if self._receiver is not None:
            self._receiver(None)
        self._queue.put_nowait(self._failure)

    def set_receiver(self, receiver: FrameReceiver) -> None:
        """Push every frame to ``receiver`` (on the loop) instead of the recv queue."""
        self._receiver = receiver

    async def recv(self, timeout: float | None = None) -> CanFrame | None:
        if self._queue.empty():
            if self._closed:
                raise ConnectionLost("CAN bus is closed")
            if self._failure is not None:
                raise self._failure
        try:
            item = self._queue.get_nowait()
        except asyncio.QueueEmpty:
            if timeout is not None and timeout <= 0:
                return None
            try:
                item = await asyncio.wait_for(self._queue.get(), timeout)
            except TimeoutError:
                return None
        if isinstance(item, BaseException):
            raise item
        return item

    def recv_nowait(self) -> CanFrame | None:
        try:
            item = self._queue.get_nowait()
        except asyncio.QueueEmpty:
            return None
        if isinstance(item, BaseException):
            raise item
        return item

    def discard_input(self) -> None:
        while not self._queue.empty():
            self._queue.get_nowait()

    # -------------------------------------------------------------- send side
    async def send(self, arbitration_id: int, data: bytes) -> None:
        if self._closed:
            raise ConnectionLost("CAN bus is closed")
        if self._failure is not None:
            raise self._failure
        if self.pacer is not None:
            await self.pacer.wait_sent(len(data))
        msg = self._can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)
        try:
            self.bus.send(msg)
        except (self._can.CanError, OSError) as exc:  # socketcand: a broken TCP socket
            raise ConnectionLost(f"CAN send failed: {exc}") from exc
        if self._traces:
            frame = CanFrame(arbitration_id, bytes(data), time.time())
            now = time.monotonic()
            for hook in self._traces:
                hook(Direction.TX, frame, now)

    def add_trace(self, hook: FrameTraceHook) -> None:
        self._traces.append(hook)

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._queue.put_nowait(ConnectionLost("CAN bus is closed"))  # wake a waiting recv
        if self._receiver is not None:
            self._receiver(None)
        if self._direct is not None:
            self._direct.close()
            if not self._owns_bus and self._direct.replaced is not None:
                _swap_queue(self.bus, self._direct, self._direct.replaced)  # the user's again
        if self._notifier is not None:
            await asyncio.to_thread(self._notifier.stop, NOTIFIER_POLL_S * 3)
        if self._owns_bus:
            await asyncio.to_thread(self.bus.shutdown)

    async def __aenter__(self) -> AsyncCanBus:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
