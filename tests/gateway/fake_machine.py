"""A machine of fake axes (the shape servobus.gateway.source.Machine asks for): a link that
can be cut or taken offline and back (as the machine's recovery does, with ``last_good``
and a power loss to acknowledge), an alarm that can be raised, and a log of what was
called, in order."""

from __future__ import annotations

import time
from collections.abc import Mapping

from servobus.axis.base import AsyncAxis
from servobus.axis.types import AxisStatus, Family
from servobus.errors import ConnectionLost, LimitError, MachineLinkError, PowerLostError


class FakeAxis:
    def __init__(self, name: str, log: list[str], url: str = "fake://line",
                 drive_id: int = 1, limits: tuple[float, float] | None = (0.0, 100.0)) -> None:
        self.name, self.url, self.drive_id, self.limits = name, url, drive_id, limits
        self.unit, self.speed_unit = "mm", "mm/s"
        self.continuous = False
        self.axis: AsyncAxis | None = None
        self.online = True
        self.family: Family | None = None
        self.protocol: str | None = "fake"
        self.pos, self.velocity, self.alarm, self.cut = 5.0, 0.0, 0, False
        self.log = log
        self.reads = 0
        self.last_error: BaseException | None = None
        self.last_good: float | None = None
        self.checking = False
        self.interrupted: str | None = None
        self.power_lost_reason: str | None = None

    @property
    def power_lost(self) -> bool:
        return self.power_lost_reason is not None

    def _link(self) -> None:
        if not self.online:  # as the machine axis: a call on an offline axis fails at once
            raise MachineLinkError(f"axis {self.name} is offline ({self.url})")
        if self.cut:
            raise ConnectionLost(f"{self.url}: cable cut")
        self.last_good = time.time()

    def drop(self, why: str = "stream closed") -> None:
        """The link went down, as the machine takes an axis offline."""
        self.online = False
        self.last_error = MachineLinkError(f"the link {self.url} is down: {why}")

    def back(self, power_lost: str | None = None) -> None:
        """The link is back (after the machine's power check: ``power_lost`` its reason)."""
        self.online, self.last_error = True, None
        self.power_lost_reason = power_lost

    async def acknowledge(self) -> None:
        self.log.append(f"{self.name} ack")
        self.power_lost_reason = self.interrupted = None

    async def position(self) -> float:
        self._link()
        self.reads += 1
        return self.pos

    async def speed(self) -> float:
        self._link()
        return self.velocity

    async def status(self) -> AxisStatus:
        self._link()
        return AxisStatus(enabled=True, moving=self.velocity != 0, in_position=True,
                          alarm_code=self.alarm, alarm_text="over current" if self.alarm else "",
                          alarm_latched=bool(self.alarm), raw=0, family="fake")

    async def readings(self) -> tuple[float, float, AxisStatus]:
        return await self.position(), await self.speed(), await self.status()

    async def move_to(self, target: float, /) -> None:
        if self.power_lost:  # as the machine axis: motion waits for the acknowledgement
            raise PowerLostError(f"axis {self.name}: the drive may have lost power")
        self._link()
        if self.limits and not self.limits[0] <= target <= self.limits[1]:
            raise LimitError(f"{target} outside")
        self.log.append(f"{self.name} move_to {target:g}")
        self.pos = target

    async def move_by(self, distance: float, /) -> None:
        await self.move_to(self.pos + distance)

    lease = None  # the fake axis takes no leases (tests/gateway/test_gateway_lease.py does)

    async def turn(self, speed: float, /, *, owner: str = "api", ttl: float = 0.5) -> None:
        self._link()
        self.log.append(f"{self.name} turn {speed:g}")
        self.velocity = speed

    async def release(self, owner: str, /) -> None:
        self.log.append(f"{self.name} release {owner}")

    async def stop(self) -> None:
        self.log.append(f"{self.name} stop")
        self.velocity = 0.0

    async def enable(self) -> None:
        self.log.append(f"{self.name} enable")

    async def disable(self) -> None:
        self.log.append(f"{self.name} disable")

    async def reset(self) -> None:
        self.log.append(f"{self.name} reset")
        self.alarm = 0


class FakeMachine:
    def __init__(self, name: str = "bench", count: int = 2) -> None:
        self.name = name
        self.log: list[str] = []
        self._axes = {f"a{i}": FakeAxis(f"a{i}", self.log, drive_id=i + 1) for i in range(count)}

    @property
    def axes(self) -> Mapping[str, FakeAxis]:
        return self._axes

    async def stop_all(self) -> dict[str, BaseException | None]:
        self.log.append("stop_all")
        for axis in self._axes.values():
            axis.velocity = 0.0
        return dict.fromkeys(self._axes)

    async def close(self) -> None:
        self.log.append("close")
