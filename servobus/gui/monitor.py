"""Live status of every axis (the Axes panel) and the alarm log (Diagnostics).

One task per axis reads status, position, speed and current every :data:`PERIOD_S`;
pages get the latest snapshot pushed over their WebSocket. A failing link is shown on the
axis (``link`` = the error) and retried after :data:`RETRY_S`; the alarm log records when
an alarm appears and clears, and when a link fails and recovers, with wall-clock times.
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


class StatusMonitor:
    def __init__(self, fleet: Fleet, period_s: float = PERIOD_S) -> None:
        self.fleet = fleet
        self.period_s = period_s
        self.snapshots: dict[int, dict[str, object]] = {
            i: {"id": i, "link": "not read yet"} for i in fleet.handles}
        self.log: deque[dict[str, object]] = deque(maxlen=LOG_KEEP)
        self._alarm: dict[int, int] = {}
        self._link_ok: dict[int, bool] = {}
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

    async def read(self, handle: AxisHandle) -> dict[str, object]:
        """One snapshot (also used right after a command, for a prompt update)."""
        axis = handle.axis
        st = await handle.call(axis.status())
        position = await handle.call(axis.position())
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

    async def _run(self, handle: AxisHandle) -> None:
        while True:
            try:
                await self.read(handle)
            except ServobusError as exc:
                text = f"{type(exc).__name__}: {exc}"
                self.snapshots[handle.id] = {**self.snapshots.get(handle.id, {}),
                                             "id": handle.id, "link": text}
                if self._link_ok.get(handle.id, True):
                    self.note(handle.id, "link", text)
                self._link_ok[handle.id] = False
                await asyncio.sleep(RETRY_S)
                continue
            if not self._link_ok.get(handle.id, True):
                self.note(handle.id, "link", "link back")
            self._link_ok[handle.id] = True
            await asyncio.sleep(self.period_s)
