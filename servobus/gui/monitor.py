"""Live status of every axis (the Axes panel) and the alarm log (Diagnostics).

One task per axis reads status, position, speed and current every :data:`PERIOD_S`;
pages get the latest snapshot pushed over their WebSocket. A failing link is shown on the
axis (``link`` = the error) and retried after :data:`RETRY_S`; the alarm log records when
an alarm appears and clears, when a link fails and recovers, when a drive may have lost
power and when that is acknowledged, with wall-clock times.

What the GUI shows is what it knows (issue 29, docs/gui.md). A failed read keeps the last
values with their time ``t``; :meth:`StatusMonitor.view` adds the machine's live link state
(AxisHandle.recovery), ``age_s`` (seconds since ``t``), ``stale_after_s``: two polling
periods as measured on this axis (the period rises at once with a slower link and decays
slowly, so a loaded host does not grey values that are fresh), and ``stale``: older than
that, or offline. The page greys stale values with "last seen N s ago" (and every value
once its statuses stop coming).

Decision: status and position are read through the machine axis (not its Axis), so every
poll stamps the machine's ``last_good`` and a lost link found by a poll takes the link
offline for reopening; speed and current are read from the Axis as before (exact rpm and
amperes; a failure there shows as ``link`` and the next poll's status read tells the
machine).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque

from servobus.errors import ServobusError
from servobus.gui.fleet import AxisHandle, Fleet

PERIOD_S = 0.1
RETRY_S = 0.5
LOG_KEEP = 500
#: A value older than this many polling periods is stale (greyed with its age by the page).
STALE_PERIODS = 2
#: How fast the measured polling period falls back after a slow read (it rises at once).
PERIOD_DECAY = 0.1


class StatusMonitor:
    def __init__(self, fleet: Fleet, period_s: float = PERIOD_S) -> None:
        self.fleet = fleet
        self.period_s = period_s
        self.snapshots: dict[int, dict[str, object]] = {
            i: {"id": i, "link": "not read yet"} for i in fleet.handles}
        self.log: deque[dict[str, object]] = deque(maxlen=LOG_KEEP)
        self._alarm: dict[int, int] = {}
        self._link_ok: dict[int, bool] = {}
        self._poll_s: dict[int, float] = {i: period_s for i in fleet.handles}
        self._flags: dict[int, tuple[str | None, str | None]] = {}
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        for handle in self.fleet.handles.values():
            self._tasks.append(asyncio.create_task(self._run(handle),
                                                   name=f"gui-status-{handle.id}"))

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks.clear()

    def note(self, axis_id: int, kind: str, text: str, code: int | None = None) -> None:
        self.log.append({"time": time.time(), "axis": axis_id, "kind": kind, "text": text,
                         "code": code})

    def view(self, axis_id: int, now: float | None = None) -> dict[str, object]:
        """The last snapshot of the axis with the machine's live link state, its age and
        when it counts as stale (module docstring): what the API and the pages get."""
        snap = self.snapshots[axis_id]
        t = snap.get("t")
        now = time.time() if now is None else now
        recovery = self.fleet.handles[axis_id].recovery()
        age = max(0.0, now - t) if isinstance(t, float) else None
        stale_after = STALE_PERIODS * self._poll_s.get(axis_id, self.period_s)
        return {**snap, **recovery, "age_s": age, "stale_after_s": stale_after,
                "stale": age is None or age > stale_after or not recovery["online"]}

    async def read(self, handle: AxisHandle) -> dict[str, object]:
        """One snapshot (also used right after a command, for a prompt update)."""
        m = handle.machine_axis
        if m is not None:  # stamps last_good; a lost link is reopened (module docstring)
            st = await handle.call(m.status())
            position = await handle.call(m.counts())
        else:
            st = await handle.call(handle.axis.status())
            position = await handle.call(handle.axis.position())
        axis = handle.axis  # after the reads above: the link may have been reopened
        speed = await handle.call(axis.speed())
        current = await handle.call(axis.current())
        snap: dict[str, object] = {
            "id": handle.id, "link": "", "t": time.time(), **st.as_dict(),
            "alarm_code": st.alarm_code, "position": position,
            "revolutions": position / axis.counts_per_rev, "speed": speed, "current": current,
            **handle.user_values(position, speed),
        }
        self._track(handle.id, st.alarm_code, st.alarm_text, st.alarm_latched)
        self.snapshots[handle.id] = snap
        return snap

    def _track(self, axis_id: int, code: int, text: str, latched: bool) -> None:
        before = self._alarm.get(axis_id, 0)
        if code != before:
            if code:
                self.note(axis_id, "alarm", f"{text}{' (latched)' if latched else ''}", code)
            else:
                self.note(axis_id, "cleared", "alarm cleared", before)
            self._alarm[axis_id] = code

    def _track_flags(self, handle: AxisHandle) -> None:
        """A power loss or an interrupted motion the machine reports: one log entry each."""
        m = handle.machine_axis
        if m is None:
            return
        now = (m.power_lost_reason, m.interrupted)
        before = self._flags.get(handle.id, (None, None))
        if now[0] is not None and now[0] != before[0]:
            self.note(handle.id, "power", f"the drive may have lost power: {now[0]}")
        if now[1] is not None and now[1] != before[1]:
            self.note(handle.id, "interrupted", f"motion interrupted: {now[1]}")
        self._flags[handle.id] = now

    def acknowledged(self, axis_id: int, what: str) -> None:
        self.note(axis_id, "ack", f"acknowledged: {what}")
        self._flags[axis_id] = (None, None)

    def _measured(self, axis_id: int, interval: float) -> None:
        """The polling period: up at once to a slower interval, down slowly."""
        before = self._poll_s.get(axis_id, self.period_s)
        self._poll_s[axis_id] = max(interval, self.period_s,
                                    before + PERIOD_DECAY * (interval - before))

    async def _run(self, handle: AxisHandle) -> None:
        last_start: float | None = None  # of the previous good read
        while True:
            start = time.monotonic()
            self._track_flags(handle)
            try:
                await self.read(handle)
                await self.fleet.trace_links()  # a reopened link: its traffic in Diagnostics
            except ServobusError as exc:
                last_start = None
                text = f"{type(exc).__name__}: {exc}"
                self.snapshots[handle.id] = {**self.snapshots.get(handle.id, {}),
                                             "id": handle.id, "link": text}
                if self._link_ok.get(handle.id, True):
                    self.note(handle.id, "link", text)
                self._link_ok[handle.id] = False
                await asyncio.sleep(RETRY_S)
                continue
            if last_start is not None:
                self._measured(handle.id, start - last_start)
            last_start = start
            if not self._link_ok.get(handle.id, True):
                self.note(handle.id, "link", "link back")
            self._link_ok[handle.id] = True
            await asyncio.sleep(self.period_s)
