"""The vendor-neutral AsyncAxis: one drive on one connection (docs/axis.md).

Units are the same on every protocol and vendor: positions in encoder counts of the drive
family (``counts_per_rev``: DMM 65,536, YZ-AIM 32,768), speeds in rpm, current in amperes
(positive = towards increasing position). Each protocol implements the abstract primitives
once; the logic that combines them (move and wait, confirmed moves, wait_idle, stop,
parameter backup) lives here once. :class:`servobus.axis.sync.Axis` runs any AsyncAxis
synchronously, method for method, without a copy of it.

What a host can know about a move (docs/axis.md; DYN2 manual 7.2: motion commands have no
reply; the same on DYN CAN, section 6):

* ``move_to``/``move_by``/``turn`` return once the command is handed to the medium: the
  argument was in range and the link was up. They cannot know whether the drive received
  the packet, was alive (a frozen or powered-off drive, a cable cut after the adapter, a
  corrupted packet the drive drops all look the same), or started to move.
* A motion command is never re-sent: a resend could move twice (relative moves) or restart
  a profile. Reads are retried; motion is not.
* ``confirm=True`` (or a ``confirm_timeout``) refuses a drive in alarm (DriveAlarm) or
  disabled (MoveFailed) before the send, and observes the drive after the one send: the
  move is confirmed when a status read shows it moving (and it was not before), or a
  position read shows the motor at the target within the in-position window or clearly
  nearer to it than before. Otherwise DriveTimeout after ``confirm_timeout``, without a
  resend; the caller decides. A move to where the motor already is cannot be observed: it
  is confirmed by the position alone. A drive still heading the same way from an earlier
  command also passes: confirmation means "seen heading to or at the target".
* ``wait=True`` waits until the drive reports the move done (``wait_idle``); on its own it
  does not prove that the move was received (a drive that never started is idle too).
"""

from __future__ import annotations

import asyncio
import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from types import TracebackType
from typing import ClassVar

from servobus import checks
from servobus.axis.capabilities import CONNECTION_CAPABILITIES, Capability
from servobus.axis.capture import Capture, CaptureSource
from servobus.axis.types import AxisStatus, Family, ParamInfo, StreamProfile
from servobus.axis.virtual_io import VirtualIo, VirtualIoSource
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveAlarm,
    DriveTimeout,
    MoveFailed,
    NotSupported,
)
from servobus.link.stats import StreamStats, TransactionStats
from servobus.transport.base import Direction

log = logging.getLogger(__name__)

#: Client-level trace hook: decoded packets/frames and the errors met (see transport.trace).
AxisTraceHook = Callable[[Direction, object, float], None]

DEFAULT_WAIT_TIMEOUT_S = 30.0
#: Default deadline of a confirmed move: a drive starts a profile within one servo cycle, so
#: half a second covers the status reads and their retries on a slow or paced link.
DEFAULT_CONFIRM_TIMEOUT_S = 0.5
#: How long ``wait_idle`` wants idle to hold (two reads at least) before it returns.
SETTLE_S = 0.02
DEFAULT_POLL_S = 0.02
#: ping_deadline where a protocol states none (a network drive: no wire time to add).
DEFAULT_PING_S = 0.05


def check_int(name: str, value: object) -> int:
    """An int (not bool, not float, not None) or ArgumentRangeError; nothing is sent."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ArgumentRangeError(f"{name} must be an integer, got {value!r}")
    return value


class AsyncAxis(ABC):
    """One drive on one connection. Every I/O method is a coroutine."""

    #: The axis may turn for ever (a spindle, a conveyor): ``?continuous=1`` on its URL or
    #: ``continuous = true`` in a machine file. Only then is open-ended motion (constant
    #: speed, a speed-mode register write) allowed without a lease (docs/safety.md).
    continuous: bool = False

    # ------------------------------------------------------------- identity
    @property
    @abstractmethod
    def drive_id(self) -> int: ...

    @property
    @abstractmethod
    def protocol(self) -> str: ...

    @property
    @abstractmethod
    def family(self) -> Family: ...

    @property
    @abstractmethod
    def drive_ids(self) -> range:
        """Every id a drive can have on this protocol (what ``scan`` tries)."""

    @property
    def counts_per_rev(self) -> int:
        return self.family.counts_per_rev

    @property
    def id_address(self) -> str | None:
        """The network address the drive id selected, where a protocol derives one from it
        (DYN5: the id is the last byte, B3.B2.B1.id); None where the id is a bus address."""
        return None

    # ------------------------------------------------------------- primitives (per protocol)
    @abstractmethod
    async def _send_move_to(self, position: int) -> None:
        """Send the absolute move to ``position`` counts; convert and range-check first."""

    @abstractmethod
    async def _send_move_by(self, distance: int) -> None:
        """Send the relative move by ``distance`` counts; convert and range-check first."""

    @abstractmethod
    async def turn(self, rpm: int) -> None:
        """Constant speed in rpm (0 ramps down and holds)."""

    @abstractmethod
    async def set_origin(self) -> None: ...

    @abstractmethod
    async def enable(self) -> None: ...

    @abstractmethod
    async def disable(self) -> None: ...

    @abstractmethod
    async def reset(self) -> None:
        """Power cycle: clears a latched alarm."""

    @abstractmethod
    async def status(self) -> AxisStatus: ...

    @abstractmethod
    async def position(self) -> int:
        """Encoder counts of the family (``counts_per_rev`` per revolution)."""

    @abstractmethod
    async def speed(self) -> float:
        """Motor speed, rpm."""

    @abstractmethod
    async def current(self) -> float:
        """Torque-producing motor current, A (positive = towards increasing position)."""

    async def readings(self) -> tuple[int, float, AxisStatus]:
        """Position (counts), speed (rpm) and status in one go, for a sampler polling many
        axes: an Axis whose :meth:`status` reads the speed itself overrides this to ask the
        drive once for the speed instead of twice."""
        position, speed, status = await asyncio.gather(self.position(), self.speed(),
                                                       self.status())
        return position, speed, status

    @abstractmethod
    def parameters(self) -> tuple[ParamInfo, ...]:
        """The family's parameters this protocol reaches (what ``params``/``set`` offer)."""

    @abstractmethod
    async def read_param(self, name: str) -> int: ...

    @abstractmethod
    async def write_param(self, name: str, value: int) -> None: ...

    @abstractmethod
    async def read_id(self) -> int: ...

    @abstractmethod
    async def assign_id(self, new_id: int) -> None:
        """After this the axis talks to ``new_id``."""

    @abstractmethod
    async def ping(self, timeout: float = 0.05) -> bool:
        """One status read, no retry; False on timeout."""

    def ping_deadline(self) -> float:
        """Seconds a ping should wait for an absent drive (what ``scan`` waits per id): the
        protocol's per-attempt reply deadline of a short read, i.e. the request and its reply
        on the wire at the link's rate plus the drive's reply time (docs/axis.md, "scan")."""
        return DEFAULT_PING_S

    @abstractmethod
    async def sibling(self, drive_id: int) -> AsyncAxis:
        """Another drive on the same connection; closing a sibling keeps the connection."""

    @abstractmethod
    async def add_trace(self, hook: AxisTraceHook) -> None: ...

    def describe_traced(self, item: object, from_drive: bool) -> str | None:
        """One item an :meth:`add_trace` hook got, in the protocol's sniff decoder's words
        (what ``servobus sniff`` shows; the GUI's traffic log asks). None: the item says
        itself (its ``describe``/``lines``), as most protocols' packets do."""
        return None

    @abstractmethod
    async def close(self) -> None: ...

    # ------------------------------------------------------------- optional features
    def on_link_lost(self, callback: Callable[[ConnectionLost], object]) -> bool:
        """Call ``callback(error)`` once when the link under this axis is lost (the peer
        closed it, the medium failed; never on ``close()``): the transport-closed signal a
        machine reopens links on. False where the protocol cannot tell; then only a call
        that fails shows it."""
        return False

    async def power_marker(self, token: int | None = None) -> int | None:
        """A cell of the drive that a power cycle clears: write ``token`` (when given), then
        return what the cell holds. None where the family has no such cell; the machine
        then judges a power loss by the position (docs/machine.md, "Recovery")."""
        return None

    #: What this protocol's connection adds to the family's capabilities, whatever the
    #: drive (a client that counts its transactions: LINK_STATS).
    protocol_capabilities: ClassVar[frozenset[Capability]] = frozenset()

    @property
    def capabilities(self) -> frozenset[Capability]:
        """What this axis can do beyond the basics (servobus.axis.capabilities): the family's
        declared set, the protocol's, and what this connection gives (a synchronised start,
        a virtual drive's trace and I/O)."""
        extra = set(self.protocol_capabilities)
        if self.sync_group() is not None:
            extra.add(Capability.SYNC_START)
        if self.capture_source is not None:
            extra.add(Capability.DRIVE_TRACE)
        if self.io_source is not None:
            extra.add(Capability.VIRTUAL_IO)
        return self.family.capabilities | extra

    def supports(self, capability: Capability) -> bool:
        return capability in self.capabilities

    def require(self, capability: Capability) -> None:
        """NotSupported (nothing is sent) when this axis lacks ``capability``."""
        if capability not in self.capabilities:
            raise self.unsupported(capability)

    def unsupported(self, capability: Capability) -> NotSupported:
        """The error for a capability this family (or this protocol) does not have."""
        if capability not in CONNECTION_CAPABILITIES:
            self.family.require(capability)  # raises when the family lacks it
        return NotSupported(f"{self.family.title} over {self.protocol} has no "
                            f"{capability.words}", family=self.family.name)

    def link_stats(self) -> TransactionStats:
        """The protocol client's transaction counters (Capability.LINK_STATS; all drives on
        the link). NotSupported where the client keeps none."""
        raise self.unsupported(Capability.LINK_STATS)

    async def home(self) -> None:
        """Start the drive's own homing, a procedure the drive runs to find its zero by
        itself; it returns once the homing is started and :meth:`wait_idle` waits for its
        end (Capability.HOMING). NotSupported, saying why and nothing sent, where the
        family's drive has no homing a host can start (docs/cli.md, "home")."""
        raise NotSupported(f"{self.family.title} over {self.protocol} has no homing a host "
                           "can start: set the zero where the axis stands "
                           "(set_origin)", family=self.family.name)

    async def following_error(self) -> float | None:
        """Commanded minus actual position (Pset - Pmotor), counts, as the drive reports it;
        None where it reports none. No manual of the families gives a readout of it on the
        wire (the DMM status has only its bound, the on-position bit |Pset - Pmotor| <=
        OnRange), so only the in-process virtual drives report theirs, through their
        internal state (:meth:`virtual_io`)."""
        source = self.io_source
        if source is None:
            return None
        value = (await source.for_drive(self.drive_id).state()).get("following_error")
        return float(value) if isinstance(value, int | float) else None

    async def set_move_profile(self, rpm: float | None = None,
                               accel_rpm_s: float | None = None) -> dict[str, int]:
        """Make point-to-point moves run at most at ``rpm`` (motor rpm) and accelerate at
        ``accel_rpm_s``, the family's own way (None: leave that one as it is). Each
        parameter is read and written only where the drive's value differs (on DMM drives
        these are EEPROM parameters: never write them per move). Returns the parameters
        written, by name (empty: the drive had them). NotSupported where the family has no
        profile a host sets; every value is checked before anything is sent."""
        speed = None if rpm is None else checks.positive("rpm", rpm, "rpm")
        accel = None if accel_rpm_s is None else checks.positive("accel_rpm_s", accel_rpm_s,
                                                                 "rpm/s")
        values = await self._move_profile_values(speed, accel)
        for name, value in values.items():
            self._check_param(name, value)
        written: dict[str, int] = {}
        for name, value in values.items():
            if await self.read_param(name) != value:
                await self.write_param(name, value)
                written[name] = value
        return written

    async def _move_profile_values(self, rpm: float | None,
                                   accel_rpm_s: float | None) -> dict[str, int]:
        """The family's parameters for a move profile (:meth:`set_move_profile`)."""
        raise NotSupported(f"{self.family.title} over {self.protocol} has no move profile a "
                           "host sets", family=self.family.name)

    async def stream_profile(self) -> StreamProfile:
        """The profile a streamed position target runs at (:meth:`stream_to`; reads the
        drive's parameters). NotSupported where the family streams no targets."""
        raise self.unsupported(Capability.STREAM_TARGETS)

    async def stream_to(self, position: int, rpm: float) -> None:
        """Move the drive's running target to ``position`` counts, a target update the drive
        follows with its own profile, never re-sent: the primitive of a lease
        (servobus.machine.lease, docs/safety.md). When no update follows, the motor comes
        to rest at the last target by itself. ``rpm`` is the speed the updates advance at;
        a family whose position moves take a cruise speed (YZ-AIM) runs them at it."""
        counts = self._check_move(position, relative=False)
        checks.positive("rpm", abs(rpm) if isinstance(rpm, int | float) else rpm, "rpm")
        await self._send_move_to(counts)

    async def stream_cycles(self, next_position: Callable[[], int | None]) -> StreamStats:
        """Cyclic synchronous position (Capability.CYCLIC_POSITION): every cycle of the
        drive's own time base, ``next_position()`` (counts, range-checked before it is
        sent) is the position the drive takes; the stream ends when it returns None, and
        the drive rests at the last position. Returns the stream's figures. A position is a
        setpoint of its cycle, not a command that could be re-sent: each cycle sends the
        one ``next_position()`` gives."""
        raise self.unsupported(Capability.CYCLIC_POSITION)

    async def stream_cycles_together(
            self, streams: Sequence[tuple[AsyncAxis, Callable[[], int | None]]],
    ) -> StreamStats:
        """Cyclic synchronous position of several axes of this axis's :meth:`sync_group` as
        one stream (Capability.CYCLIC_GROUP): each cycle one position per axis and one
        synchronisation signal for the group, so they take their positions together. Every
        ``next_position()`` is asked each cycle; the stream ends for all when any returns
        None or a position is out of range (nothing of that cycle is sent), and every drive
        rests at its last position."""
        raise self.unsupported(Capability.CYCLIC_GROUP)

    async def square_wave(self, amplitude: int) -> None:
        """Drive-generated square-wave test motion (families with "waves")."""
        raise self.unsupported(Capability.WAVES)

    async def sine_wave(self, amplitude: int) -> None:
        """Drive-generated sine-wave test motion (families with "waves")."""
        raise self.unsupported(Capability.WAVES)

    async def wave_frequency(self, hz: int) -> None:
        raise self.unsupported(Capability.WAVES)

    def sync_group(self) -> object | None:
        """A synchronised start: axes whose ``sync_group()`` is the same (non-None) object can
        start absolute moves with one trigger (:meth:`sync_move_to`), e.g. drives on one bus
        with a broadcast start. None (the default): this axis has no synchronised start.
        The machine (servobus.machine) asks this instead of naming a protocol."""
        return None

    async def sync_move_to(self, moves: Sequence[tuple[AsyncAxis, int]]) -> None:
        """Absolute moves (counts) of axes of this axis's :meth:`sync_group`, loaded first
        and started by one trigger; every target is checked before anything is sent."""
        raise self.unsupported(Capability.SYNC_START)

    def _check_sync_moves(self, moves: Sequence[tuple[AsyncAxis, int]]) -> None:
        """Every axis in this axis's sync group, every target in range (nothing sent)."""
        group = self.sync_group()
        for axis, counts in moves:
            if group is None or axis.sync_group() is not group:
                raise ArgumentRangeError(f"{axis!r} does not start together with {self!r}")
            axis._check_move(counts, relative=False)

    async def save_parameters(self) -> None:
        """Keep the parameters written so far over a power cycle, where the family saves
        with a command (YZ-AIM save flag 0x14). NotSupported elsewhere: DMM DYN2/DYN4
        writes reach EEPROM as they are made, DYN5 writes over EtherNet/IP cannot be kept."""
        raise NotSupported(f"{self.family.title} over {self.protocol} has no save command",
                           family=self.family.name)

    #: Where :meth:`trace_buffer` reads; set by the in-process virtual drives
    #: (servobus.sim.core.capture), None on a link to a drive that keeps no trace.
    capture_source: CaptureSource | None = None

    async def trace_buffer(self) -> Capture:
        """The drive's own samples (position, position error, speed, current, status) taken
        since the previous call, in the Axis units (servobus.axis.capture). The first call
        starts the recording. NotSupported where the drive keeps no such trace: poll."""
        source = self.capture_source
        if source is None:
            raise NotSupported(f"{self.family.title} over {self.protocol} keeps no sample "
                               "trace a host can read; poll the axis", family=self.family.name)
        return source.read(self.drive_id).rescaled(self.counts_per_rev)

    #: Where :meth:`virtual_io` reaches the drive's connector I/O; set on the in-process
    #: virtual drives of the DMM families (servobus.sim.schemes), None on a real drive.
    io_source: VirtualIoSource | None = None

    def virtual_io(self) -> VirtualIo:
        """A virtual drive's JP3 inputs and outputs (servobus.axis.virtual_io): analog
        reference, pulse train, ENA, outputs, internal state. NotSupported on a real drive."""
        source = self.io_source
        if source is None:
            raise NotSupported(f"{self.family.title} over {self.protocol} is not a virtual "
                               "drive with connector I/O", family=self.family.name)
        return source.for_drive(self.drive_id)

    # ------------------------------------------------------------- units
    def param_info(self, name: str) -> ParamInfo:
        """A reachable parameter by name; ArgumentRangeError naming what exists."""
        for p in self.parameters():
            if p.name == name:
                return p
        raise ArgumentRangeError(
            f"{name!r} is not a parameter {self.protocol} reaches on {self.family.title}; "
            f"known: {', '.join(p.name for p in self.parameters())}")

    def revs(self, revolutions: float) -> int:
        """Revolutions -> counts of this axis (rounded half away from zero)."""
        return self.family.revs_to_counts(revolutions)

    def degrees(self, degrees: float) -> int:
        """Degrees -> counts of this axis (rounded half away from zero)."""
        return self.family.degrees_to_counts(degrees)

    def _check_move(self, value: object, *, relative: bool) -> int:
        """Check a move argument before anything is sent: an int within :meth:`_move_limits`."""
        counts = check_int("distance" if relative else "position", value)
        self._check_limits(counts, relative)
        return counts

    def _move_limits(self, relative: bool) -> tuple[int, int] | None:
        """Counts a move to (or by) can reach with what the axis knows now; None: no limit.

        Protocols whose range depends on a drive setting (DMM GEAR_NUM) give the widest
        range until they have read it, then the exact one (:meth:`move_range`)."""
        return None

    def _check_limits(self, counts: int, relative: bool) -> None:
        limits = self._move_limits(relative)
        if limits is not None and not limits[0] <= counts <= limits[1]:
            what = "a move by" if relative else "a move to"
            raise ArgumentRangeError(
                f"{what} {counts} counts is outside {limits[0]}..{limits[1]} counts, "
                f"the range of {self.family.title} over {self.protocol}"
                f"{self._limits_note()}")

    def _limits_note(self) -> str:
        """What the range depends on, for the error message (e.g. " at GEAR_NUM 4096")."""
        return ""

    async def move_range(self, *, relative: bool = False) -> tuple[int, int] | None:
        """The counts a move to (``relative``: by) can reach on this drive, None if
        unbounded (reads what the range depends on, e.g. DMM GEAR_NUM, when needed)."""
        return self._move_limits(relative)

    async def position_window(self) -> int:
        """Counts within which the drive reports "in position" (protocols read the drive's)."""
        return max(1, self.counts_per_rev // 1024)

    # ------------------------------------------------------------- shared logic (once)
    async def move_to(self, position: int, *, wait: bool = False, timeout: float | None = None,
                      confirm: bool = False, confirm_timeout: float | None = None) -> None:
        """Absolute move to ``position`` counts.

        Returns when the command is sent; the drive never answers a move (module doc:
        what a host can know). ``confirm=True`` (or ``confirm_timeout``) then verifies that
        the drive took it (DriveTimeout if not, never re-sent); ``wait=True`` then waits
        until the move is done (``timeout``, default 30 s).
        """
        await self._move(position, False, wait, timeout, confirm, confirm_timeout)

    async def move_by(self, distance: int, *, wait: bool = False, timeout: float | None = None,
                      confirm: bool = False, confirm_timeout: float | None = None) -> None:
        """Relative move by ``distance`` counts; as :meth:`move_to` (never re-sent)."""
        await self._move(distance, True, wait, timeout, confirm, confirm_timeout)

    async def _move(self, value: int, relative: bool, wait: bool, timeout: float | None,
                    confirm: bool, confirm_timeout: float | None) -> None:
        self._check_move(value, relative=relative)
        wait_s = checks.optional_seconds("timeout", timeout)
        confirm_s = checks.optional_seconds("confirm_timeout", confirm_timeout)
        if confirm or confirm_s is not None:
            await self._confirmed_move(value, relative, DEFAULT_CONFIRM_TIMEOUT_S
                                       if confirm_s is None else confirm_s)
        elif relative:
            await self._send_move_by(value)
        else:
            await self._send_move_to(value)
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if wait_s is None else wait_s)

    async def _confirmed_move(self, value: int, relative: bool, deadline_s: float) -> None:
        """Read where the drive is, send the move once, then observe that it took it.

        The reads before the send may fail (DriveTimeout, ...): then nothing was sent. A
        drive in alarm (DriveAlarm) or disabled (MoveFailed) would not take the move: it is
        refused before the send (issue 28).
        """
        tolerance = await self.position_window()
        before = await self.status()
        self._raise_alarm(before)
        if not before.enabled:
            raise MoveFailed(f"drive {self.drive_id} is disabled (motor free): the move was "
                             "not sent; enable it first", drive_id=self.drive_id)
        was_busy = before.moving
        start = await self.position()
        target = start + value if relative else value
        if relative:
            await self._send_move_by(value)
        else:
            await self._send_move_to(value)
        await self._confirm(target, start, tolerance, was_busy, deadline_s)

    async def _confirm(self, target: int, start: int, tolerance: int, was_busy: bool,
                       deadline_s: float) -> None:
        """Poll status and position until the move shows, the drive alarms (DriveAlarm)
        or ``deadline_s`` passes (DriveTimeout). Read failures are retried until then."""
        deadline = time.monotonic() + deadline_s
        start_gap = abs(start - target)
        seen = "no reply"
        while True:
            try:
                st = await self.status()
                self._raise_alarm(st)
                if st.moving and not was_busy:
                    return
                position = await self.position()
            except DriveTimeout as exc:
                seen = f"reads failed ({exc})"
            else:
                gap = abs(position - target)
                if gap <= tolerance or gap < start_gap - tolerance:
                    return
                seen = f"position {position}, moving={st.moving}"
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriveTimeout(
                    f"drive {self.drive_id} did not take the move to {target} counts "
                    f"within {deadline_s:g} s (started at {start}; {seen}); the move was "
                    "sent once and is not re-sent")
            await asyncio.sleep(min(DEFAULT_POLL_S, remaining))

    def _raise_alarm(self, st: AxisStatus) -> None:
        if st.alarm_latched:
            raise DriveAlarm(
                f"drive {self.drive_id} alarm {st.alarm_code}: {st.alarm_text} (latched: "
                "a reset or power cycle clears it)", code=st.alarm_code, drive_id=self.drive_id)

    async def stop(self) -> None:
        """Constant speed 0: the drive ramps down at its deceleration and holds position."""
        await self.turn(0)

    async def wait_idle(self, timeout: float = DEFAULT_WAIT_TIMEOUT_S,
                        poll: float = DEFAULT_POLL_S) -> AxisStatus:
        """Poll status until motion is done and the motor is on position, and stays so.

        Decision: a servo rings around its target after a move; a status read at a zero
        crossing of that ring says idle while the next one still says moving. So ``idle``
        must hold on two reads at least ``SETTLE_S`` apart (every read between them idle
        too) before this returns - a status read right after it says idle as well.
        Raises DriveAlarm as soon as a latched alarm shows, DriveTimeout when ``timeout``
        passes. ``timeout`` must be finite and > 0, ``poll`` finite and >= 0.
        """
        timeout_s = checks.seconds("timeout", timeout)
        poll_s = checks.non_negative_seconds("poll", poll)
        deadline = time.monotonic() + timeout_s
        idle_since: float | None = None
        while True:
            st = await self.status()
            self._raise_alarm(st)
            now = time.monotonic()
            if not st.idle:
                idle_since = None
            elif idle_since is None:
                idle_since = now
            elif now - idle_since >= SETTLE_S:
                return st
            remaining = deadline - time.monotonic()
            if idle_since is not None:  # settling: the next read after the window
                await asyncio.sleep(max(0.0, min(SETTLE_S - (now - idle_since), remaining)))
                if remaining <= 0:
                    return st  # idle at the deadline: not a timeout
                continue
            if remaining <= 0:
                raise DriveTimeout(
                    f"drive {self.drive_id} still moving after {timeout_s:g} s "
                    f"(moving={st.moving}, in_position={st.in_position})")
            await asyncio.sleep(min(poll_s, remaining))

    async def read_params(self, names: Iterable[str] | None = None) -> dict[str, int]:
        """Read parameters (default: every one this protocol reaches)."""
        wanted = [p.name for p in self.parameters()] if names is None else list(names)
        for name in wanted:
            self.param_info(name)
        return {name: await self.read_param(name) for name in wanted}

    async def write_params(self, values: Mapping[str, int]) -> None:
        """Write several parameters; every value is checked before the first byte is sent."""
        for name, value in values.items():
            self._check_param(name, value)
        for name, value in values.items():
            await self.write_param(name, value)

    def _check_param(self, name: str, value: object) -> int:
        """Range-check one parameter write against the family table (protocols add more)."""
        return self.param_info(checks.param_name(name)).check(value)

    async def __aenter__(self) -> AsyncAxis:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.close()
