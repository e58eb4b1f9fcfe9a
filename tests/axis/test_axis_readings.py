"""``AsyncAxis.readings()``: what a sampler polls per axis, on every protocol's virtual drive.

It must agree with ``position()``, ``speed()`` and ``status()`` and ask the drive for the speed
once: DMM command axes and DYN5 read the speed inside ``status()`` when no profile runs, and
the gateway's sampler polling 32 axes at 50 Hz paid that read twice.
"""

from __future__ import annotations

import pytest
from rig import wait_until_async

from servobus.axis import registry
from servobus.axis.connect import connect_async

URLS = [f"sim://{spec.name}?fast=1" for spec in registry.specs().values() if spec.sim]

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("url", URLS)
async def test_readings_read_the_speed_once_and_agree(url: str) -> None:
    axis = await connect_async(url, drive_id=1, timeout=0.5)
    try:
        await axis.turn(300)

        async def at_speed() -> bool:
            return abs(await axis.speed() - 300) <= 30

        await wait_until_async(at_speed, what="300 rpm")
        speed_calls = 0
        speed = axis.speed

        async def counted() -> float:
            nonlocal speed_calls
            speed_calls += 1
            return await speed()

        axis.speed = counted  # type: ignore[method-assign]
        position, rpm, status = await axis.readings()
        assert speed_calls == 1
        assert status.moving  # a constant speed: moving from the speed, not the busy bit
        assert abs(rpm - 300) <= 30
        assert abs(position - await axis.position()) <= axis.counts_per_rev  # 300 rpm, ms apart
    finally:
        await axis.stop()
        await axis.close()
