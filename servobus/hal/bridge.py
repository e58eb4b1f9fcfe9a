"""The component's loop: machine axes <-> HAL pins (docs/linuxcnc.md).

One task per axis runs cycles as fast as its link answers (at least ``PERIOD_S`` apart):
it reads the input pins, acts on their edges, streams the position command (``position``
axes), then reads the drive and writes the output pins. Another task watches the watchdog.

Safety decisions (docs/safety.md, docs/linuxcnc.md; sync groups: servobus.hal.cyclic_group):

* a position axis streams only between an ``enable`` rising edge and the next fault or
  falling edge; a stopped axis never resumes by itself: after any fault it needs
  ``fault-reset`` and a new ``enable`` rising edge;
* a command step beyond the file's ``speed``/``accel`` is refused (nothing sent), the axis
  stopped and faulted (:mod:`servobus.hal.step_guard`);
* the watchdog starving (no toggle for ``watchdog_s``) stops every position axis and faults
  every axis until it toggles again and ``fault-reset`` rises;
* a link lost while streaming faults the axis (the motion is never resumed on the reopened
  link); the drive rests at the last target;
* a monitor axis (step/dir from elsewhere) is never stopped by the component: it only
  raises ``fault``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Sequence

from servobus.axis.capabilities import Capability
from servobus.errors import LimitError, MachineLinkError, ServobusError
from servobus.hal.cyclic_group import CyclicGroup
from servobus.hal.pins import Pins, axis_pin
from servobus.hal.step_guard import StepGuard, StepRefused
from servobus.hal.watchdog import Clock, Watchdog
from servobus.link.stats import StreamStats
from servobus.machine.axis import AsyncMachineAxis

log = logging.getLogger(__name__)

#: The least time between two cycles of one axis (a link that answers at once is not
#: polled harder than this).
PERIOD_S = 0.002
#: Current and the drive's following error are read every this many cycles (extra reads).
SLOW_EVERY = 10
#: How long a stop waits for a cyclic stream to end (it ends at its next cycle: 2 ms).
CYCLIC_END_S = 1.0

class AxisBridge:
    """One machine axis and its pins (``<axis>.<pin>``)."""

    def __init__(self, axis: AsyncMachineAxis, pins: Pins, starved: Callable[[], bool],
                 clock: Clock = time.monotonic,
                 group_of: Callable[[AxisBridge], tuple[CyclicGroup, list[AxisBridge]] | None]
                 = lambda _: None) -> None:
        self.axis = axis
        self.pins = pins
        self.position_mode = axis.spec.hal == "position"
        self._starved = starved
        self._clock = clock
        self.latched: str | None = None  # a fault that holds until fault-reset
        self.streaming = False
        #: Streamed (so possibly moving) since its last completed stop: a stop of an axis
        #: already stopped and not streamed since sends nothing (the exit after the enable's
        #: fall; servobus.hal.cyclic_group stops its axes too). True at start: the first
        #: stop always goes out.
        self.moved = True
        self._enable = False
        self._reset = False
        self._alarm = False
        self.cycles = 0
        self._target: float | None = None
        self._guard: StepGuard | None = None
        #: The running cyclic stream (Capability.CYCLIC_POSITION), None otherwise.
        self._cyclic: asyncio.Task[None] | None = None
        self.cyclic_stats: StreamStats | None = None  # the last cyclic stream's figures
        #: Where the drives stream as one group (Capability.CYCLIC_GROUP): its group and
        #: that group's position axes now (servobus.hal.cyclic_group).
        self._group_of = group_of
        self._group: CyclicGroup | None = None
        if self.position_mode:
            speed, accel = axis.spec.speed, axis.spec.accel
            assert speed is not None and accel is not None  # the machine file requires them
            self._guard = StepGuard(speed, accel, axis.unit)

    def pin(self, name: str) -> str:
        return axis_pin(self.axis.name, name)

    @property
    def fault(self) -> bool:
        return (not self.axis.online or self._alarm or self.latched is not None
                or self._starved())

    def latch(self, why: str) -> None:
        """A fault that holds until fault-reset (one log line)."""
        if self.latched is None:
            log.warning("axis %s: fault: %s", self.axis.name, why)
        self.latched = why
        self.streaming = False

    async def cycle(self) -> None:
        """One round: inputs, streaming, readings, outputs."""
        self.cycles += 1
        try:
            await self._inputs()
            if self.streaming:
                await self._stream()
            await self._read()
        except MachineLinkError as exc:
            if self.streaming:
                self.latch(f"the link dropped while streaming ({exc})")
            self.streaming = False
        except ServobusError as exc:  # a timeout, a refused call: next cycle tries again
            log.debug("axis %s: %s", self.axis.name, exc)
        self.outputs()

    async def _inputs(self) -> None:
        enable = bool(self.pins[self.pin("enable")])
        reset = bool(self.pins[self.pin("fault-reset")])
        rose_reset = reset and not self._reset
        self._reset = reset
        if rose_reset:
            await self._fault_reset()
        if enable != self._enable:
            self._enable = enable
            if enable:
                await self._enabled()
            else:
                await self._disabled()

    async def _fault_reset(self) -> None:
        log.info("axis %s: fault-reset", self.axis.name)
        self.latched = None
        core = self.axis.axis
        if self._alarm and core is not None and core.supports(Capability.RESET):
            await self.axis.reset()

    async def _enabled(self) -> None:
        await self.axis.enable()
        if not self.position_mode or self._guard is None:
            return
        if self.fault:
            log.warning("axis %s: enable while faulted: not streaming (fault-reset, then "
                        "enable again)", self.axis.name)
            return
        target = float(self.pins[self.pin("position-cmd")])
        try:
            self._guard.join(self._clock(), target, await self.axis.position())
        except StepRefused as exc:
            await self._refuse(exc)
            return
        self._target = None
        self.streaming = self.moved = True
        core = self.axis.axis
        grouped = self._group_of(self)
        if grouped is not None:
            group, members = grouped
            if group.join(self, members):
                self._group = group
                log.info("axis %s: enabled, streaming position-cmd every cycle of the drive "
                         "in its sync group (%s) once all of it is enabled", self.axis.name,
                         group.names)
            else:
                self.streaming = False
                log.warning("axis %s: its sync group (%s) streams without it: not streaming "
                            "(disable the group's axes, then enable them together)",
                            self.axis.name, group.names)
        elif core is not None and core.supports(Capability.CYCLIC_POSITION):
            self._cyclic = asyncio.create_task(self._run_cyclic(),
                                               name=f"hal cyclic {self.axis.name}")
            log.info("axis %s: enabled, streaming position-cmd every cycle of the drive",
                     self.axis.name)
        else:
            log.info("axis %s: enabled, streaming position-cmd as target updates",
                     self.axis.name)

    async def _disabled(self) -> None:
        await self.stop()
        await self.axis.disable()

    async def _refuse(self, exc: StepRefused) -> None:
        self.latch(f"refused: {exc}; nothing was sent, the axis stopped")
        await self.stop()

    async def stop(self) -> None:
        """Stop a position axis (nothing for a monitor axis: step/dir drives it); a cyclic
        stream ends first (its next cycle sees ``streaming`` off)."""
        self.streaming = False
        group = self._group
        if group is not None:
            # every axis of the group stops (cyclic_group); the group is forgotten only once
            # its stream has ended and its axes stopped, so that a stop cancelled meanwhile
            # (SIGTERM while the enable's fall stops the axis) is followed by one that waits
            # for that stream again instead of racing it
            await group.leave(self)
            self._group = None
        cyclic, self._cyclic = self._cyclic, None
        if cyclic is not None and cyclic is not asyncio.current_task():
            try:
                await asyncio.wait_for(cyclic, CYCLIC_END_S)
            except TimeoutError:
                log.warning("axis %s: the cyclic stream did not end within %g s: cancelled",
                            self.axis.name, CYCLIC_END_S)
        if self.position_mode and self.moved:
            with contextlib.suppress(ServobusError):
                await self.axis.stop()
                self.moved = False

    async def _run_cyclic(self) -> None:
        """The drive's cyclic stream, fed by :meth:`_next_cyclic` until it returns None."""
        try:
            self.cyclic_stats = await self.axis.stream_cycles(self.next_cyclic)
        except ServobusError as exc:
            self.latch(f"the cyclic stream failed: {exc}")
        if self.latched is not None:
            self._cyclic = None  # stop() from here must not wait for itself
            await self.stop()

    def next_cyclic(self) -> float | None:
        """One cycle's target: position-cmd, checked; None ends the stream."""
        assert self._guard is not None
        if not self.streaming or self.fault:
            return None
        target = float(self.pins[self.pin("position-cmd")])
        if target != self._target:
            try:
                self._guard.check(self._clock(), target)
            except StepRefused as exc:
                self.latch(f"refused: {exc}; nothing was sent, the axis stopped")
                return None
            self._target = target
        return self._target

    async def _stream(self) -> None:
        assert self._guard is not None and self.axis.spec.speed is not None
        if self.fault:
            await self.stop()
            return
        if self._cyclic is not None or self._group is not None:
            return  # the cyclic stream sends (its own task, or its group's)
        target = float(self.pins[self.pin("position-cmd")])
        if self._target is not None and target == self._target:
            return  # no new command: nothing to send (never re-sent)
        try:
            self._guard.check(self._clock(), target)
        except StepRefused as exc:
            await self._refuse(exc)
            return
        self._target = target
        try:
            await self.axis.stream_target(target, self.axis.spec.speed)
        except LimitError as exc:  # checked before sending: nothing went out
            self.latch(f"refused: {exc}")
            await self.stop()

    async def _read(self) -> None:
        position, speed, status = await self.axis.readings()
        self._alarm = status.alarm
        pins = self.pins
        pins[self.pin("position-fb")] = position
        pins[self.pin("velocity-fb")] = speed
        pins[self.pin("enabled")] = status.enabled
        pins[self.pin("moving")] = status.moving
        pins[self.pin("in-position")] = status.in_position
        pins[self.pin("alarm-code")] = int(status.alarm_code)
        if self.position_mode:
            command = float(pins[self.pin("position-cmd")])
            pins[self.pin("following-error")] = command - position if self.streaming else 0.0
        if self.cycles % SLOW_EVERY == 1:
            pins[self.pin("current")] = await self.axis.current()
            if not self.position_mode:
                error = await self.axis.following_error()
                pins[self.pin("following-error")] = 0.0 if error is None else error

    def outputs(self) -> None:
        self.pins[self.pin("online")] = self.axis.online
        self.pins[self.pin("fault")] = self.fault


class Bridge:
    """Every axis of the machine, the component's ``fault`` and its watchdog."""

    def __init__(self, axes: Sequence[AsyncMachineAxis], pins: Pins, watchdog_s: float,
                 clock: Clock = time.monotonic) -> None:
        self.pins = pins
        self.watchdog = Watchdog(pins, watchdog_s, clock)
        self.axes = [AxisBridge(a, pins, lambda: self.watchdog.starved, clock,
                                self._group_of) for a in axes]
        self._groups: list[CyclicGroup] = []
        for bridge in self.axes:  # what holds before the first cycle: faulted, not fed
            bridge.outputs()
        self._component_fault()

    async def run(self) -> None:
        """Until cancelled; the caller stops the position axes afterwards (:meth:`stop`)."""
        async with asyncio.TaskGroup() as group:
            for bridge in self.axes:
                group.create_task(self._axis_loop(bridge), name=f"hal {bridge.axis.name}")
            group.create_task(self._watch_loop(), name="hal watchdog")

    async def _axis_loop(self, bridge: AxisBridge) -> None:
        while True:
            started = time.monotonic()
            await bridge.cycle()
            self._component_fault()
            await asyncio.sleep(max(0.0, PERIOD_S - (time.monotonic() - started)))

    async def _watch_loop(self) -> None:
        while True:
            if self.watchdog.poll():
                for bridge in self.axes:
                    bridge.latch(f"the watchdog stopped toggling for "
                                 f"{self.watchdog.timeout_s:g} s")
                await self.stop()
            self._component_fault()
            await asyncio.sleep(PERIOD_S)

    def _group_of(self, bridge: AxisBridge,
                  ) -> tuple[CyclicGroup, list[AxisBridge]] | None:
        """The sync group of a position axis and its position axes now (the axes whose
        drives stream as one group: ``AsyncMachineAxis.cyclic_group``), or None."""
        key = bridge.axis.cyclic_group() if bridge.position_mode else None
        if key is None:
            return None
        members = [b for b in self.axes if b.position_mode and b.axis.cyclic_group() is key]
        group = next((g for g in self._groups if g.key is key), None)
        if group is None:
            self._groups = [g for g in self._groups if g.task is not None]  # links reopened
            group = CyclicGroup(key)
            self._groups.append(group)
        return group, members

    def _component_fault(self) -> None:
        self.pins["fault"] = self.watchdog.starved or any(b.fault for b in self.axes)

    async def stop(self) -> None:
        """Stop every position axis at once (the watchdog, the component's exit)."""
        await asyncio.gather(*(b.stop() for b in self.axes))
