"""The synchronous Axis: the one async core, run for a caller that blocks on each result.

A *runner* runs the core's coroutines: :class:`LoopThread`, a private event loop on a daemon
thread that each call hops to and back, or - for a link that needs no loop between calls -
:class:`servobus.axis.inline.InlineRunner`, which runs the call on the caller's own thread
(issue 22; :func:`servobus.axis.connect.connect` chooses). Hooks registered through the
facade run where the loop runs: on the loop thread, or on the calling thread during a call.

Decision (issue 19): the facade is an explicit typed class, one method per method of
:class:`~servobus.axis.base.AsyncAxis` with the same parameters and the coroutine's result
as a plain return type, so a checker sees ``connect(...).position()`` as ``int`` and flags
``axis.move_too(5)``. tests/axis/test_axis_sync_facade.py fails when the two drift. Every
call goes through :meth:`Axis._call` and the axis's runner: the fast path for synchronous
callers (issue 22) is a runner, not a second facade. What a protocol has
beyond the Axis API is reached through ``axis.extra`` (typed ``Any`` on purpose: it
depends on the protocol) or, asynchronously where the loop runs, ``axis.core``.
"""

from __future__ import annotations

import _thread
import asyncio
import contextlib
import functools
import inspect
import threading
from collections.abc import Callable, Coroutine, Iterable, Mapping, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any, ParamSpec, Protocol, TypeVar

from servobus import fastloop
from servobus.axis.base import DEFAULT_POLL_S, DEFAULT_WAIT_TIMEOUT_S
from servobus.errors import ClosedError, ConnectionLost, DriveTimeout

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis, AxisTraceHook
    from servobus.axis.capabilities import Capability
    from servobus.axis.capture import Capture
    from servobus.axis.types import AxisStatus, Family, ParamInfo, StreamProfile
    from servobus.axis.virtual_io import VirtualIo
    from servobus.link.stats import StreamStats, TransactionStats

T = TypeVar("T")
P = ParamSpec("P")


class Runner(Protocol):
    """What the facade needs of a runner: run one coroutine for a blocking caller."""

    def run(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """The coroutine's result (its exception propagates); ``timeout`` is a safety net."""
        ...

    def stop(self) -> None:
        """Release the loop (and its thread); idempotent."""
        ...

    @property
    def stopped(self) -> bool:
        ...


class LoopThread:
    """Owns an asyncio loop running on its own daemon thread until :meth:`stop`.

    ``loop``: run this (not running) loop instead of a new one - how an
    :class:`~servobus.axis.inline.InlineRunner` hands its loop over.
    """

    def __init__(self, name: str = "servobus-loop",
                 loop: asyncio.AbstractEventLoop | None = None) -> None:
        # uvloop with servobus[fast] (issue 22)
        self.loop = fastloop.new_event_loop() if loop is None else loop
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        self._started.wait()
        self._stopped = False

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.call_soon(self._started.set)
        self.loop.run_forever()

    def run(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """Run ``coro`` on the loop and wait for its result (exceptions propagate).

        ``timeout`` (a safety net: the core enforces the deadlines) raises TimeoutError;
        it and Ctrl-C cancel the coroutine on the loop, so a transaction in progress is
        given up by its own rules (its reply, if it comes, is owed and dropped).

        Decision (issue 22): one task and one bare lock per call instead of
        ``asyncio.run_coroutine_threadsafe`` (a concurrent Future with its Condition and
        two chained callbacks): the same hop to the loop thread and back, about a third
        less CPU per call (benchmarks/bench_enip.py prints the breakdown).
        """
        if self._stopped:
            coro.close()
            raise ClosedError("the connection is closed")
        if threading.current_thread() is self._thread:
            coro.close()
            raise ClosedError("sync facade called from its own loop thread (use the async API)")
        call = _Call(coro)
        try:
            self.loop.call_soon_threadsafe(call.start, self.loop)
        except RuntimeError:  # the loop was closed under us
            coro.close()
            raise ClosedError("the connection is closed") from None
        try:
            if not call.done.acquire(timeout=-1 if timeout is None else timeout):
                raise DriveTimeout(f"no result within {timeout} s")
        except BaseException:  # the timeout above, or Ctrl-C while waiting
            with contextlib.suppress(RuntimeError):
                self.loop.call_soon_threadsafe(call.cancel)
            raise
        result: T = call.result()
        return result

    def stop(self) -> None:
        """Stop the loop and join the thread; idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(5.0)
        if not self.loop.is_running():
            self.loop.close()

    @property
    def stopped(self) -> bool:
        return self._stopped


class _Call:
    """One coroutine run for a thread waiting on :attr:`done` (a bare lock, held until the
    task is finished)."""

    __slots__ = ("_cancelled", "_coro", "_task", "done")

    def __init__(self, coro: Coroutine[Any, Any, Any]) -> None:
        self._coro = coro
        self._task: asyncio.Task[Any] | None = None
        self._cancelled = False
        self.done = _thread.allocate_lock()
        self.done.acquire()

    def start(self, loop: asyncio.AbstractEventLoop) -> None:  # on the loop thread
        if self._cancelled:  # given up before it started: never sent anything
            self._coro.close()
            return
        self._task = loop.create_task(self._coro)
        self._task.add_done_callback(self._finished)

    def _finished(self, _task: asyncio.Task[Any]) -> None:
        self.done.release()

    def cancel(self) -> None:  # on the loop thread
        self._cancelled = True
        if self._task is not None:
            self._task.cancel()

    def result(self) -> Any:
        assert self._task is not None
        return self._task.result()


class Axis:
    """Synchronous facade over any AsyncAxis: the same methods, run by the facade's runner.

    Each method has the AsyncAxis method's parameters and returns what its coroutine returns
    (module docstring). ``sibling`` returns an Axis sharing the connection. Hooks registered
    through the facade run where the loop runs. A protocol's own methods: ``axis.extra``.
    """

    def __init__(self, core: AsyncAxis, runner: Runner, *, owns_runner: bool = True,
                 call_timeout: float | None = None) -> None:
        self._core = core
        self._runner = runner
        self._owns_runner = owns_runner
        self._call_timeout = call_timeout  # safety net only; the core enforces deadlines
        self._extra = Extras(self)

    def _call(self, method: Callable[P, Coroutine[Any, Any, T]], *args: P.args,
              **kwargs: P.kwargs) -> T:
        """Run one coroutine method of the core and wait for it: every call passes here."""
        return self._runner.run(method(*args, **kwargs), self._call_timeout)

    # ------------------------------------------------------------- beyond the Axis API
    @property
    def core(self) -> AsyncAxis:
        """The async core (for use where the facade's loop runs only: its coroutines are bound
        to that loop)."""
        return self._core

    @property
    def extra(self) -> Any:
        """The protocol's own methods beyond the Axis API, run synchronously like the rest
        (``axis.extra.config()`` on a DMM drive over DYN232M); untyped: they depend on the
        protocol. AttributeError for a method this protocol does not have."""
        return self._extra

    # ------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return self._core.drive_id

    @property
    def protocol(self) -> str:
        return self._core.protocol

    @property
    def family(self) -> Family:
        return self._core.family

    @property
    def drive_ids(self) -> range:
        """Every id a drive can have on this protocol (what ``scan`` tries)."""
        return self._core.drive_ids

    @property
    def counts_per_rev(self) -> int:
        return self._core.counts_per_rev

    @property
    def continuous(self) -> bool:
        """The axis may turn for ever (``?continuous=1``; docs/safety.md)."""
        return self._core.continuous

    @property
    def id_address(self) -> str | None:
        """The network address the drive id selected (DYN5), None where the id is a bus address."""
        return self._core.id_address

    # ------------------------------------------------------------- capabilities
    @property
    def capabilities(self) -> frozenset[Capability]:
        """What this axis can do beyond the basics (:attr:`AsyncAxis.capabilities`)."""
        return self._core.capabilities

    def supports(self, capability: Capability) -> bool:
        return self._core.supports(capability)

    def require(self, capability: Capability) -> None:
        """NotSupported (nothing is sent) when this axis lacks ``capability``."""
        self._core.require(capability)

    def link_stats(self) -> TransactionStats:
        """The protocol client's transaction counters (Capability.LINK_STATS)."""
        return self._core.link_stats()

    # ------------------------------------------------------------- motion
    def move_to(self, position: int, *, wait: bool = False, timeout: float | None = None,
                confirm: bool = False, confirm_timeout: float | None = None) -> None:
        """Absolute move to ``position`` counts (:meth:`AsyncAxis.move_to`)."""
        return self._call(self._core.move_to, position, wait=wait, timeout=timeout,
                          confirm=confirm, confirm_timeout=confirm_timeout)

    def move_by(self, distance: int, *, wait: bool = False, timeout: float | None = None,
                confirm: bool = False, confirm_timeout: float | None = None) -> None:
        """Relative move by ``distance`` counts (:meth:`AsyncAxis.move_by`; never re-sent)."""
        return self._call(self._core.move_by, distance, wait=wait, timeout=timeout,
                          confirm=confirm, confirm_timeout=confirm_timeout)

    def stream_profile(self) -> StreamProfile:
        """The profile a streamed position target runs at (reads the drive)."""
        return self._call(self._core.stream_profile)

    def stream_to(self, position: int, rpm: float) -> None:
        """Move the drive's running target to ``position`` counts (a lease's primitive;
        docs/safety.md)."""
        return self._call(self._core.stream_to, position, rpm)

    def stream_cycles(self, next_position: Callable[[], int | None]) -> StreamStats:
        """Cyclic synchronous position: ``next_position()`` every cycle of the drive, until
        it returns None (:meth:`AsyncAxis.stream_cycles`)."""
        return self._call(self._core.stream_cycles, next_position)

    def stream_cycles_together(
            self, streams: Sequence[tuple[Axis, Callable[[], int | None]]]) -> StreamStats:
        """Cyclic synchronous position of several axes of this axis's sync group as one
        stream (:meth:`AsyncAxis.stream_cycles_together`)."""
        return self._call(self._core.stream_cycles_together,
                          [(axis.core, next_position) for axis, next_position in streams])

    def turn(self, rpm: int) -> None:
        """Constant speed in rpm (0 ramps down and holds)."""
        return self._call(self._core.turn, rpm)

    def stop(self) -> None:
        """Constant speed 0: the drive ramps down at its deceleration and holds position."""
        return self._call(self._core.stop)

    def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                  poll: float = DEFAULT_POLL_S) -> AxisStatus:
        """Poll status until motion is done (:meth:`AsyncAxis.wait_idle`)."""
        return self._call(self._core.wait_idle, timeout, poll)

    def set_origin(self) -> None:
        return self._call(self._core.set_origin)

    def home(self) -> None:
        """Start the drive's own homing; NotSupported saying why where it has none."""
        return self._call(self._core.home)

    def set_move_profile(self, rpm: float | None = None,
                         accel_rpm_s: float | None = None) -> dict[str, int]:
        """Point-to-point speed and acceleration, written only where the drive differs
        (:meth:`AsyncAxis.set_move_profile`); the parameters written."""
        return self._call(self._core.set_move_profile, rpm, accel_rpm_s)

    def enable(self) -> None:
        return self._call(self._core.enable)

    def disable(self) -> None:
        return self._call(self._core.disable)

    def reset(self) -> None:
        """Power cycle: clears a latched alarm."""
        return self._call(self._core.reset)

    def square_wave(self, amplitude: int) -> None:
        return self._call(self._core.square_wave, amplitude)

    def sine_wave(self, amplitude: int) -> None:
        return self._call(self._core.sine_wave, amplitude)

    def wave_frequency(self, hz: int) -> None:
        return self._call(self._core.wave_frequency, hz)

    # ------------------------------------------------------------- reading
    def status(self) -> AxisStatus:
        return self._call(self._core.status)

    def position(self) -> int:
        """Encoder counts of the family (``counts_per_rev`` per revolution)."""
        return self._call(self._core.position)

    def speed(self) -> float:
        """Motor speed, rpm."""
        return self._call(self._core.speed)

    def current(self) -> float:
        """Torque-producing motor current, A (positive = towards increasing position)."""
        return self._call(self._core.current)

    def following_error(self) -> float | None:
        """Pset - Pmotor, counts, where the drive reports it; None where it does not."""
        return self._call(self._core.following_error)

    def position_window(self) -> int:
        """Counts within which the drive reports "in position"."""
        return self._call(self._core.position_window)

    def readings(self) -> tuple[int, float, AxisStatus]:
        """Position (counts), speed (rpm) and status together, the speed read once."""
        return self._call(self._core.readings)

    def ping_deadline(self) -> float:
        """Seconds a ping waits for an absent drive (what ``scan`` waits per id)."""
        return self._core.ping_deadline()

    def move_range(self, *, relative: bool = False) -> tuple[int, int] | None:
        """The counts a move to (``relative``: by) can reach on this drive, None if unbounded."""
        return self._call(self._core.move_range, relative=relative)

    def on_link_lost(self, callback: Callable[[ConnectionLost], object]) -> bool:
        """``callback(error)`` once when the link is lost (called on the loop's thread)."""
        return self._core.on_link_lost(callback)

    def power_marker(self, token: int | None = None) -> int | None:
        """Write ``token`` into the drive's power-cleared cell and read it back; None where
        the family has none (:meth:`AsyncAxis.power_marker`)."""
        return self._call(self._core.power_marker, token)

    def ping(self, timeout: float = 0.05) -> bool:
        """One status read, no retry; False on timeout."""
        return self._call(self._core.ping, timeout)

    def save_parameters(self) -> None:
        """Keep the parameters over a power cycle (:meth:`AsyncAxis.save_parameters`)."""
        return self._call(self._core.save_parameters)

    def trace_buffer(self) -> Capture:
        """The drive's own samples since the previous call (:meth:`AsyncAxis.trace_buffer`)."""
        return self._call(self._core.trace_buffer)

    def virtual_io(self) -> VirtualIo:
        """A virtual drive's connector I/O; NotSupported on a real drive."""
        return self._core.virtual_io()

    # ------------------------------------------------------------- parameters and id
    def parameters(self) -> tuple[ParamInfo, ...]:
        """The family's parameters this protocol reaches."""
        return self._core.parameters()

    def param_info(self, name: str) -> ParamInfo:
        return self._core.param_info(name)

    def read_param(self, name: str) -> int:
        return self._call(self._core.read_param, name)

    def write_param(self, name: str, value: int) -> None:
        return self._call(self._core.write_param, name, value)

    def read_params(self, names: Iterable[str] | None = None) -> dict[str, int]:
        """Read parameters (default: every one this protocol reaches)."""
        return self._call(self._core.read_params, names)

    def write_params(self, values: Mapping[str, int]) -> None:
        """Write several parameters; every value is checked before the first byte is sent."""
        return self._call(self._core.write_params, values)

    def read_id(self) -> int:
        return self._call(self._core.read_id)

    def assign_id(self, new_id: int) -> None:
        """After this the axis talks to ``new_id``."""
        return self._call(self._core.assign_id, new_id)

    # ------------------------------------------------------------- units
    def revs(self, revolutions: float) -> int:
        """Revolutions -> counts of this axis (rounded half away from zero)."""
        return self._core.revs(revolutions)

    def degrees(self, degrees: float) -> int:
        """Degrees -> counts of this axis (rounded half away from zero)."""
        return self._core.degrees(degrees)

    # ------------------------------------------------------------- connection
    def add_trace(self, hook: AxisTraceHook) -> None:
        """``hook(direction, item, t)``; it runs where the loop runs (module docstring)."""
        return self._call(self._core.add_trace, hook)

    def describe_traced(self, item: object, from_drive: bool) -> str | None:
        """An :meth:`add_trace` hook's item in the sniff decoder's words (None: it says
        itself)."""
        return self._core.describe_traced(item, from_drive)

    def sync_group(self) -> object | None:
        """Axes with the same (non-None) group start absolute moves with one trigger."""
        return self._core.sync_group()

    def sync_move_to(self, moves: Sequence[tuple[Axis, int]]) -> None:
        """Absolute moves (counts) of axes of this axis's sync group, started together."""
        self._call(self._core.sync_move_to, [(axis.core, counts) for axis, counts in moves])

    def sibling(self, drive_id: int) -> Axis:
        """Another drive on the same connection; closing it keeps the connection."""
        core = self._call(self._core.sibling, drive_id)
        return Axis(core, self._runner, owns_runner=False, call_timeout=self._call_timeout)

    def close(self) -> None:
        """Close the axis (the connection too unless this is a sibling); idempotent."""
        if self._runner.stopped:
            return
        try:
            self._call(self._core.close)
        finally:
            if self._owns_runner:
                self._runner.stop()

    def __enter__(self) -> Axis:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Axis {self._core.protocol} id {self._core.drive_id}>"


class Extras:
    """``axis.extra``: any public attribute of the core; its coroutine methods run
    synchronously through the facade, its plain attributes are read through."""

    def __init__(self, axis: Axis) -> None:
        self._axis = axis

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        attr = getattr(self._axis.core, name)
        if not inspect.iscoroutinefunction(attr):
            return attr

        @functools.wraps(attr)
        def call(*args: Any, **kwargs: Any) -> Any:
            return self._axis._call(attr, *args, **kwargs)

        return call

    def __dir__(self) -> list[str]:
        return sorted(n for n in dir(self._axis.core) if not n.startswith("_"))

    def __repr__(self) -> str:
        return f"<extras of {self._axis!r}>"
