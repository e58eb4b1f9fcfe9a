"""The axes the GUI serves: one connection (a drive URL) or a machine file.

Both are a machine (servobus.machine), so jog, constant speed and waves take one path
(leases, owners, soft limits; issue 27). One URL (:meth:`Fleet.open`) is a machine of one
axis per id (``open_url_machine_async``): the first id opens the connection, the others are
its siblings (the same line or bus); the GUI keys them by drive id and shows them as before
(counts and rpm, no names). With no URL it runs on :data:`DEFAULT_URL`, three in-process
virtual drives. On ``sim://`` the ids become the virtual drives' ids unless the URL names
its own.

A machine (:meth:`Fleet.open_machine`, servobus.machine): every axis of every link and vendor,
keyed 1..n in file order (drive ids repeat across links, so the GUI's axis number is the
axis's place in the file), named as in the file, with its unit and limits in the identity
and its position/speed in that unit in every status. Links open with ``retry=True``: an
axis whose link is down shows its link error and comes back when the link does (the page
then asks for its identity again); a link that drops later is reopened by the machine, and
:meth:`Fleet.trace_links` hooks the traffic log onto every link opened since. A jog or
constant speed never passes a soft limit (its lease's target stops there); the machine's
guard still watches for motion from outside (a wave run from another program).
"""

from __future__ import annotations

import inspect
import weakref
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar, cast

from servobus.axis.base import AsyncAxis
from servobus.axis.capabilities import Capability
from servobus.axis.units import round_counts
from servobus.errors import ArgumentRangeError
from servobus.gui.link_stats import CallStats, client_counters
from servobus.gui.signals import SIGNALS
from servobus.gui.traffic import TrafficLog

if TYPE_CHECKING:
    from servobus.machine import AsyncMachine, AsyncMachineAxis

T = TypeVar("T")
#: The scope signals shown in the axis's position unit, and in its speed unit.
POSITION_SIGNALS = ("position", "position_error")
SPEED_SIGNALS = ("speed",)


@dataclass(frozen=True)
class Units:
    """What the page shows an axis in (issue 33): a machine file's axis in its own unit
    (mm, deg, ...) and that unit per second; an axis of a bare URL in its drive family's
    counts and rpm. ``per_count``/``per_rpm``: the shown value of one count / one rpm."""

    position: str = "counts"
    speed: str = "rpm"
    per_count: float = 1.0
    per_rpm: float = 1.0

    def signal(self, name: str, unit: str) -> tuple[str, float]:
        """A scope signal's shown unit and factor (raw value x factor); ``unit``: its
        raw unit (servobus.gui.signals)."""
        if name in POSITION_SIGNALS:
            return self.position, self.per_count
        if name in SPEED_SIGNALS:
            return self.speed, self.per_rpm
        return unit, 1.0

    def as_dict(self, signals: dict[str, str]) -> dict[str, object]:
        return {"position": self.position, "speed": self.speed,
                "per_count": self.per_count, "per_rpm": self.per_rpm,
                "signals": {n: self.signal(n, u)[0] for n, u in signals.items()}}

DEFAULT_URL = "sim://dyn232?fast=1"
DEFAULT_IDS = (1, 2, 3)


class _OfflineAxis:
    """Stands in for the Axis of an offline machine axis: a coroutine method raises its
    MachineLinkError when awaited (so STOP ALL and the monitor go on with the others);
    anything else (family, parameters(), ...) raises it at once."""

    def __init__(self, machine_axis: AsyncMachineAxis) -> None:
        self._machine_axis = machine_axis

    def __getattr__(self, name: str) -> Callable[..., Awaitable[object]]:
        if not inspect.iscoroutinefunction(getattr(AsyncAxis, name, None)):
            self._machine_axis.core()  # raises MachineLinkError

        async def offline(*args: object, **kwargs: object) -> object:
            return self._machine_axis.core()  # raises MachineLinkError

        return offline


@dataclass
class AxisHandle:
    """One axis and what the GUI counts about it (on a machine: its name, unit, limits)."""

    base_axis: AsyncAxis | None
    stats: CallStats = field(default_factory=CallStats)
    key: int | None = None  # the GUI's axis number (machine file: its place; URL: drive id)
    machine_axis: AsyncMachineAxis | None = None
    #: A machine file's axis: shown by its name, in its unit. False for an axis of a bare
    #: URL (a one-axis-per-id machine in counts): shown as a drive, in counts and rpm.
    named: bool = True

    @property
    def axis(self) -> AsyncAxis:
        m = self.machine_axis
        if m is not None:
            return m.axis if m.axis is not None else cast(AsyncAxis, _OfflineAxis(m))
        assert self.base_axis is not None
        return self.base_axis

    @property
    def id(self) -> int:
        return self.key if self.key is not None else self.axis.drive_id

    @property
    def label(self) -> str:
        """How messages name the axis: ``axis x`` (its machine name) or ``axis 2``."""
        m = self.machine_axis
        return f"axis {m.name}" if m is not None and self.named else f"axis {self.id}"

    def units(self) -> Units:
        """The units the page shows this axis in (counts and rpm until a machine axis's
        link is online: its counts per revolution come from the drive)."""
        m = self.machine_axis
        if m is None or not self.named or not m.online:
            return Units()
        scale = m.scale
        return Units(m.unit, m.speed_unit, 1.0 / scale.counts_per_unit, scale.from_rpm(1.0))

    def to_rpm(self, speed: float) -> float:
        """A speed in the axis's shown speed unit -> motor rpm."""
        return speed / self.units().per_rpm

    def to_counts(self, value: float) -> int:
        """A distance in the axis's shown position unit -> counts (rounded)."""
        return round_counts(value / self.units().per_count)

    def user_values(self, position: float, speed: float) -> dict[str, object]:
        """Position and speed in the machine axis's unit (nothing on a plain connection)."""
        m = self.machine_axis
        if m is None or not m.online or not self.named:
            return {}
        return {"name": m.name, "unit": m.unit, "user_position": m.to_user(position),
                "user_speed": m.scale.from_rpm(speed), "speed_unit": m.speed_unit}

    async def call(self, awaitable: Awaitable[T]) -> T:
        return await self.stats.timed(awaitable)

    def identity(self) -> dict[str, object]:
        m = self.machine_axis
        named: dict[str, object] = {
            "title": self.label,
            "units": self.units().as_dict({n: g.unit for n, g in SIGNALS.items()})}
        if m is not None:
            named["continuous"] = m.continuous  # constant speed is open-ended (issue 27)
        if m is not None and self.named:
            named.update({
                "name": m.name, "unit": m.unit, "speed_unit": m.speed_unit, "url": m.url,
                "drive_id": m.drive_id, "limits": list(m.limits) if m.limits else None,
                "default_speed": m.default_speed, "label": m.spec.label, "online": m.online})
        if m is not None and not m.online:  # what the page can show until it comes back
            return {"id": self.id, "protocol": "", "family": "", "family_title": "offline",
                    "counts_per_rev": 1, "capabilities": [], "alarms": {}, "params": 0,
                    "virtual_io": False, **named}
        a = self.axis
        fam = a.family
        if m is not None and self.named:
            named["counts_per_unit"] = m.scale.counts_per_unit
        return {
            "id": self.id, "protocol": a.protocol, "family": fam.name,
            "family_title": fam.title, "counts_per_rev": a.counts_per_rev,
            "capabilities": sorted(a.capabilities),
            "alarms": {str(k): v for k, v in fam.alarms.items()},
            "params": len(a.parameters()),
            "virtual_io": a.supports(Capability.VIRTUAL_IO),
            **named,
        }

    def recovery(self) -> dict[str, object]:
        """What the machine knows of the axis's link and drive (issue 29, docs/gui.md):
        ``online``, ``last_good`` (``time.time()`` of its last good call, None before
        one), ``interrupted`` (the motion the drop cut short, never re-sent),
        ``power_lost`` and its reason, ``checking`` (a reopened link checked for a power
        loss). Read live at each status, not from the last poll."""
        m = self.machine_axis
        if m is None:  # a fleet built from plain Axes: no machine to ask
            return {"online": True, "last_good": None, "interrupted": None,
                    "power_lost": False, "power_lost_reason": None, "checking": False}
        return {"online": m.online, "last_good": m.last_good, "interrupted": m.interrupted,
                "power_lost": m.power_lost, "power_lost_reason": m.power_lost_reason,
                "checking": m.checking}

    def link(self) -> dict[str, object]:
        return {"gui": self.stats.as_dict(), "client": client_counters(self.axis)}


class Fleet:
    """The GUI's axes by number; ``machine`` runs their motion (None only for a fleet built
    by hand from plain axes); ``machine_file``: it came from a machine file (named axes)."""

    def __init__(self, url: str, handles: Sequence[AxisHandle], traffic: TrafficLog,
                 machine: AsyncMachine | None = None, *, machine_file: bool = True) -> None:
        self.url = url
        self.handles = {h.id: h for h in handles}
        self.traffic = traffic
        self.machine = machine
        self.machine_file = machine is not None and machine_file
        #: Link owners whose traffic reaches ``traffic``: those open now were hooked by
        #: whoever opened the fleet (open_machine, open, the gateway's bridge).
        self._traced: weakref.WeakSet[AsyncAxis] = weakref.WeakSet(
            link.owner for link in (machine.links if machine is not None else ())
            if link.owner is not None)

    async def trace_links(self) -> None:
        """Hook the traffic log onto every link opened since (after start-up, or reopened
        after a drop: a fresh Axis), so Diagnostics keeps showing its traffic."""
        if self.machine is None:
            return
        for link in self.machine.links:
            owner = link.owner
            if owner is not None and owner not in self._traced:
                self._traced.add(owner)
                await owner.add_trace(self.traffic.hook_for(owner))

    @classmethod
    async def open_machine(cls, path: str | Path | None = None) -> Fleet:
        """Every axis of the machine file ``path`` (None: the built-in virtual machine)."""
        from servobus.machine import open_machine_async

        machine = await open_machine_async(path, retry=True)
        try:
            traffic = TrafficLog()
            for link in machine.links:  # siblings share their owner's trace
                if link.owner is not None:
                    await link.owner.add_trace(traffic.hook_for(link.owner))
            machine.guard_limits()
        except BaseException:
            await machine.close()
            raise
        handles = [AxisHandle(None, key=i, machine_axis=a)
                   for i, a in enumerate(machine.axes.values(), start=1)]
        return cls(machine.source, handles, traffic, machine)

    @classmethod
    async def open(cls, url: str | None = None, ids: Sequence[int] | None = None) -> Fleet:
        """Open ``url`` (default: three virtual drives) as a machine of one axis per id."""
        from servobus.machine import open_url_machine_async

        url = url or DEFAULT_URL
        if ids is None and url == DEFAULT_URL:
            ids = DEFAULT_IDS
        wanted: list[int | None] = list(ids) if ids else [None]
        if len(set(wanted)) != len(wanted):
            raise ArgumentRangeError(f"duplicate drive ids {wanted}")
        machine = await open_url_machine_async(url, wanted, retry=False)
        try:
            traffic = TrafficLog()
            for link in machine.links:  # siblings share the connection's trace
                if link.owner is not None:
                    await link.owner.add_trace(traffic.hook_for(link.owner))
        except BaseException:
            await machine.close()
            raise
        handles = [AxisHandle(None, key=a.core().drive_id, machine_axis=a, named=False)
                   for a in machine.axes.values()]
        return cls(url, handles, traffic, machine, machine_file=False)

    def get(self, drive_id: int) -> AxisHandle:
        try:
            return self.handles[drive_id]
        except KeyError:
            raise ArgumentRangeError(f"no axis {drive_id}; axes: "
                                     f"{', '.join(map(str, self.handles))}") from None

    async def close(self) -> None:
        """The machine: leases ended, every axis stopped, then closed (siblings first)."""
        if self.machine is not None:
            await self.machine.close()
            return
        for handle in reversed(list(self.handles.values())):
            await handle.axis.close()
