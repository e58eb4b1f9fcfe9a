"""The axes the GUI serves: one connection (a drive URL), one AsyncAxis per drive id.

The first id opens the connection (``connect_async``); the others are its siblings (the
same line or bus). With no URL the GUI runs on :data:`DEFAULT_URL`, three in-process
virtual drives. On ``sim://`` the ids become the virtual drives' ids unless the URL names
its own.
"""

from __future__ import annotations

from collections.abc import Awaitable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from servobus.axis.base import AsyncAxis
from servobus.axis.connect import connect_async
from servobus.errors import ArgumentRangeError
from servobus.gui.link_stats import CallStats, client_counters
from servobus.gui.traffic import TrafficLog

T = TypeVar("T")
DEFAULT_URL = "sim://dyn232?fast=1"
DEFAULT_IDS = (1, 2, 3)


@dataclass
class AxisHandle:
    """One axis and what the GUI counts about it."""

    axis: AsyncAxis
    stats: CallStats = field(default_factory=CallStats)

    @property
    def id(self) -> int:
        return self.axis.drive_id

    async def call(self, awaitable: Awaitable[T]) -> T:
        return await self.stats.timed(awaitable)

    def identity(self) -> dict[str, object]:
        a = self.axis
        fam = a.family
        return {
            "id": a.drive_id, "protocol": a.protocol, "family": fam.name,
            "family_title": fam.title, "counts_per_rev": a.counts_per_rev,
            "features": sorted(fam.features),
            "alarms": {str(k): v for k, v in fam.alarms.items()},
            "params": len(a.parameters()),
            "virtual_io": a.io_source is not None,
        }

    def link(self) -> dict[str, object]:
        return {"gui": self.stats.as_dict(), "client": client_counters(self.axis)}


class Fleet:
    def __init__(self, url: str, handles: Sequence[AxisHandle], traffic: TrafficLog) -> None:
        self.url = url
        self.handles = {h.id: h for h in handles}
        self.traffic = traffic

    @classmethod
    async def open(cls, url: str | None = None, ids: Sequence[int] | None = None) -> Fleet:
        """Open ``url`` (default: three virtual drives) and an axis per id."""
        url = url or DEFAULT_URL
        if ids is None and url == DEFAULT_URL:
            ids = DEFAULT_IDS
        wanted: list[int | None] = list(ids) if ids else [None]
        if len(set(wanted)) != len(wanted):
            raise ArgumentRangeError(f"duplicate drive ids {wanted}")
        options: dict[str, object] = {}
        if url.startswith("sim:") and "ids=" not in url and ids:
            options["ids"] = ",".join(str(i) for i in ids)
        first = await connect_async(url, drive_id=wanted[0], **options)
        axes = [first]
        try:
            for drive_id in ids[1:] if ids else ():
                sib = await first.sibling(drive_id)
                if sib.capture_source is None:
                    sib.capture_source = first.capture_source  # same connection
                if sib.io_source is None:
                    sib.io_source = first.io_source
                axes.append(sib)
            traffic = TrafficLog()
            await first.add_trace(traffic.hook)  # siblings share the connection
        except BaseException:
            for a in reversed(axes):
                await a.close()
            raise
        return cls(url, [AxisHandle(a) for a in axes], traffic)

    def get(self, drive_id: int) -> AxisHandle:
        try:
            return self.handles[drive_id]
        except KeyError:
            raise ArgumentRangeError(f"no axis {drive_id}; axes: "
                                     f"{', '.join(map(str, self.handles))}") from None

    async def close(self) -> None:
        """Siblings first, the connection's owner last."""
        for handle in reversed(list(self.handles.values())):
            await handle.axis.close()
