"""Jog and constant speed from a page: leases of the machine axis, owned by the page.

Every axis the GUI serves is a machine axis (servobus.gui.fleet), so a jog or a constant
speed is the machine's lease (servobus.machine.lease, docs/safety.md): position targets
streamed a bounded lead ahead of the motor, never past a soft limit, ending by themselves
``lease_s`` (the ttl, at most 1 s) after the last renewal, in the drive too if this
process dies. Decisions:

* The owner is the page: ``page N``, N its WebSocket session number (``hello``'s
  ``owner``). The page renews a jog by repeating ``jog`` every 150 ms while the button is
  held, and a constant speed by repeating ``turn`` while it is on; a page that stops
  renewing (a frozen tab, a pulled cable with the socket still open) ends within the ttl,
  a closed or dropped WebSocket at once (:meth:`JogControl.release`).
* One owner per axis: another page's jog or constant speed is refused with the machine's
  OwnerError naming the holder. Stop and STOP ALL always win.
* A renewal never restarts a motion that ended without the page letting go (Stop, STOP
  ALL, a lease that ran out, a failed link): the page's next ``jog``/``turn`` for that
  axis is refused (:class:`MotionEnded`) until it sends ``jog_stop``/``turn_stop`` (the
  button goes up), and the status tells the page why it ended. Only a new press (or Run)
  starts again.
* On a ``continuous`` axis (no limits, ``continuous = true`` or ``?continuous=1``) constant
  speed is open-ended, as the file says: it runs until Stop, not renewed, and outlives the
  page; the answer says ``open_ended`` and the page shows it.
* A REST client (``POST /api/axes/N/turn`` without ``page``) owns its constant speed as
  ``rest`` and renews it by posting again within its ttl.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from servobus.errors import ArgumentRangeError, ConnectionLost, ServobusError
from servobus.gui.fleet import AxisHandle, Fleet
from servobus.machine.axis import AsyncMachineAxis
from servobus.machine.lease import DEFAULT_TTL_S, Lease, check_ttl

log = logging.getLogger(__name__)

#: The ttl of a page's lease, seconds: the page renews every 150 ms.
LEASE_S = DEFAULT_TTL_S
MAX_JOG_RPM = 6000
REST_OWNER = "rest"


class MotionEnded(ServobusError):
    """The page's jog or constant speed ended without the page letting go (Stop, STOP ALL,
    not renewed in time, a link failure): a renewal does not start it again."""


def page_owner(page: int) -> str:
    return f"page {page}"


@dataclass
class Held:
    """What one page holds on one axis: the lease the GUI started for it."""

    kind: str  # "jog" or "turn"
    speed: float  # in the axis's shown speed unit (servobus.gui.fleet.Units)
    lease: Lease | None


class JogControl:
    def __init__(self, fleet: Fleet, lease_s: float = LEASE_S) -> None:
        self.fleet = fleet
        self.lease_s = check_ttl(lease_s)
        self.held: dict[tuple[int, int], Held] = {}  # (page, axis) -> its motion
        self.pages: set[int] = set()  # the pages connected now
        self.stops = 0  # motions ended by a page letting go (release, page left)
        self.closed = False  # the GUI is shutting down: no new motion

    def start(self) -> None:
        """Nothing to watch: each lease ends by itself (servobus.machine.lease)."""

    async def stop(self) -> None:
        """Shutdown step: every page lets go (the axes were stopped before)."""
        for page, axis_id in list(self.held):
            await self.release(page, axis_id)

    def close(self) -> None:
        """The GUI shuts down (its stop of every axis follows): no new motion from here."""
        self.closed = True

    # ------------------------------------------------------------- from a page
    async def jog(self, page: int, axis_id: int, speed: float) -> None:
        """Start or renew ``page``'s jog of ``axis_id`` at ``speed`` (the axis's shown
        speed unit: a machine axis's unit per second, rpm on a bare URL; 0 = release)."""
        await self._hold("jog", page, axis_id, speed, start=None)

    async def turn(self, axis_id: int, speed: float, *, page: int | None = None,
                   ttl: float | None = None, start: bool = True) -> dict[str, object]:
        """Constant speed: started by Run (REST, ``start``) and renewed by the page's
        ``turn`` messages; without ``page`` a REST client's (owner ``rest``, renewed by
        posting again). ``open_ended``: a continuous axis, not leased."""
        if page is not None and page not in self.pages:
            raise ArgumentRangeError(f"no page {page} is connected: constant speed needs "
                                     "the page's WebSocket, which renews it")
        if page is None:
            return await self._rest_turn(axis_id, speed, ttl)
        return await self._hold("turn", page, axis_id, speed, start=start)

    async def release(self, page: int, axis_id: int | None = None) -> None:
        """The button went up (``axis_id``), or every motion of ``page`` (it left)."""
        owner = page_owner(page)
        for key in [k for k in self.held if k[0] == page and axis_id in (None, k[1])]:
            held = self.held.pop(key)
            if held.lease is None or not held.lease.alive:
                continue  # it had ended already
            m = self._machine_axis(self.fleet.get(key[1]))
            self.stops += 1
            try:
                await m.release(owner)
            except ServobusError as exc:  # the lease ends anyway; the log says why
                label = self.fleet.get(key[1]).label
                log.warning("release of %s by %s failed: %s", label, owner, exc)

    # ------------------------------------------------------------- what the page is shown
    def active(self) -> dict[int, dict[str, object]]:
        """Every axis's running lease: owner, rpm, speed in the axis's shown unit, at the
        soft limit."""
        out: dict[int, dict[str, object]] = {}
        for i, h in self.fleet.handles.items():
            m = h.machine_axis
            lease = m.lease if m is not None else None
            if m is not None and lease is not None and m.online:
                rpm = m.scale.to_rpm(lease.speed)
                units = h.units()
                out[i] = {"owner": lease.owner, "rpm": round(rpm),
                          "speed": rpm * units.per_rpm, "speed_unit": units.speed,
                          "at_limit": lease.at_limit}
        return out

    def ended(self, page: int) -> dict[int, str]:
        """``page``'s motions that ended without it letting go, and why."""
        return {axis: (h.lease.ended if h.lease is not None else "") or "ended"
                for (p, axis), h in self.held.items()
                if p == page and h.lease is not None and not h.lease.alive}

    # ------------------------------------------------------------- inside
    def _machine_axis(self, handle: AxisHandle) -> AsyncMachineAxis:
        m = handle.machine_axis
        if m is None:
            raise ArgumentRangeError(f"{handle.label} has no machine axis: no jog")
        return m

    def _check(self, handle: AxisHandle, speed: float) -> float:
        """``speed`` (shown unit) -> the machine axis's user units per second, checked."""
        if self.closed:
            raise ConnectionLost("the GUI is shutting down: every axis is being stopped")
        units = handle.units()
        if isinstance(speed, bool) or not isinstance(speed, int | float) \
                or not math.isfinite(speed) or abs(speed / units.per_rpm) > MAX_JOG_RPM:
            top = MAX_JOG_RPM * abs(units.per_rpm)
            raise ArgumentRangeError(f"{handle.label}: a jog speed is a number of "
                                     f"{units.speed} within +-{top:g}, got {speed!r}")
        m = self._machine_axis(handle)
        return float(speed) if handle.named else m.scale.from_rpm(speed / units.per_rpm)

    async def _hold(self, kind: str, page: int, axis_id: int, shown: float,
                    *, start: bool | None) -> dict[str, object]:
        """``start``: True a new Run (replaces an ended one), False a renewal only, None a
        jog message (a renewal while held, else a new press)."""
        handle = self.fleet.get(axis_id)
        speed = self._check(handle, shown)
        m = self._machine_axis(handle)
        key, owner = (page, axis_id), page_owner(page)
        held = self.held.get(key)
        if speed == 0:
            await self.release(page, axis_id)
            return {"open_ended": False}
        if held is not None and (held.lease is None or not held.lease.alive) and not start:
            why = held.lease.ended if held.lease is not None else ""
            again = "release and press again" if held.kind == "jog" else "press Run again"
            raise MotionEnded(f"the {held.kind} of {handle.label} ended"
                              f"{f' ({why})' if why else ''}; {again}")
        if held is None and start is False:
            raise MotionEnded(f"no {kind} of this page on {handle.label} to renew; "
                              "press Run again")
        if kind == "turn" and m.continuous:
            m.check_owner(owner)
            await handle.call(m.turn(speed, owner=owner, ttl=self.lease_s))
            self.held.pop(key, None)
            return {"open_ended": True}
        if kind == "turn":
            await handle.call(m.turn(speed, owner=owner, ttl=self.lease_s))
        else:
            await handle.call(m.jog(speed, owner=owner, ttl=self.lease_s))
        self.held[key] = Held(kind, shown, m.lease)
        return {"open_ended": False, "ttl": self.lease_s}

    async def _rest_turn(self, axis_id: int, shown: float,
                         ttl: float | None) -> dict[str, object]:
        handle = self.fleet.get(axis_id)
        speed = self._check(handle, shown)
        m = self._machine_axis(handle)
        ttl = check_ttl(self.lease_s if ttl is None else ttl)
        if m.continuous:
            m.check_owner(REST_OWNER)
        await handle.call(m.turn(speed, owner=REST_OWNER, ttl=ttl))
        return {"open_ended": m.continuous, "ttl": None if m.continuous else ttl}
