"""A machine on in-process virtual links: units, limits before the wire, shared links,
stop_all, move_together, offline links."""

from __future__ import annotations

import asyncio
from pathlib import Path

import machine_rig
import pytest
from machine_rig import write_machine
from rig import wait_until_async

import servobus
from servobus.axis import registry
from servobus.errors import ArgumentRangeError, LimitError, MachineLinkError, NotSupported
from servobus.machine import AsyncMachine, open_machine_async, parse_quantity
from servobus.transport.base import Direction


async def open_mixed(tmp_path: Path) -> AsyncMachine:
    return await open_machine_async(write_machine(tmp_path))


async def test_units_through_the_family_counts(tmp_path: Path) -> None:
    async with await open_mixed(tmp_path) as m:
        x, y, c = m["x"], m["y"], m["c"]
        assert (x.family and x.family.counts_per_rev, c.family and c.family.counts_per_rev) \
            == (65536, 32768)
        assert x.to_counts(12.5) == 163840  # 12.5 mm / 5 mm per rev x 65,536
        assert y.to_counts(12.5) == -163840  # direction = -1
        assert c.to_counts(90) == 8192  # a quarter of 32,768
        assert c.to_user(16384) == 180.0
        await x.move_to(12.5, wait=True, timeout=10)
        assert abs(await x.position() - 12.5) < 0.01
        assert abs(await x.counts() - 163840) < 64
        await c.move_to(-90, wait=True, timeout=10)
        assert abs(await c.position() + 90) < 0.5


async def test_speed_is_user_units_per_second(tmp_path: Path) -> None:
    async with await open_mixed(tmp_path) as m:
        c = m["c"]
        assert c.scale.to_rpm(360.0) == 60.0  # one revolution per second
        await c.turn(360.0)
        speed = await wait_until_async(lambda: _at_speed(c, 360.0), timeout=10,
                                       what="c at 360 deg/s")
        assert speed
        await c.stop()


async def _at_speed(axis: object, want: float) -> bool:
    from servobus.machine import AsyncMachineAxis

    assert isinstance(axis, AsyncMachineAxis)
    return abs(await axis.speed() - want) < want * 0.05


def test_quantities_in_the_axis_unit() -> None:
    assert parse_quantity("12.5", "mm") == (12.5, "mm")
    assert parse_quantity("12.5mm", "mm") == (12.5, "mm")
    assert parse_quantity("-90deg", "deg") == (-90.0, "deg")
    assert parse_quantity("100counts", "deg") == (100.0, "counts")
    with pytest.raises(ArgumentRangeError, match=r"axis c is in deg, not mm") as info:
        parse_quantity("12.5mm", "deg", axis="c")
    assert "\n" not in str(info.value)
    with pytest.raises(ArgumentRangeError):
        parse_quantity("12.5furlong", "mm")
    with pytest.raises(ArgumentRangeError):
        parse_quantity("1.5counts", "mm")


async def test_limits_are_refused_before_the_wire(tmp_path: Path) -> None:
    async with await open_mixed(tmp_path) as m:
        x, c = m["x"], m["c"]
        sent: list[object] = []
        for axis in (x, c):
            await axis.core().add_trace(
                lambda d, data, t: sent.append(data) if d is Direction.TX else None)
        await x.position()
        assert sent, "the trace hook sees what is sent"
        sent.clear()
        with pytest.raises(LimitError, match=r"axis x: 300.5 mm is outside the soft limits"):
            await x.move_to(300.5)
        with pytest.raises(LimitError):
            await x.move_by(400.0)  # longer than the travel: no read either
        with pytest.raises(LimitError):
            await m.move_together({"x": 10.0, "c": 721.0})
        with pytest.raises(ArgumentRangeError, match="finite number"):
            await x.move_to(float("nan"))
        assert sent == []
        assert isinstance(LimitError("x"), ArgumentRangeError)


async def test_relative_moves_and_turns_stop_at_the_limit(tmp_path: Path) -> None:
    """A turn is a lease whose target never passes the limit: the motor rests at it, and a
    further turn that way is refused with nothing sent (issue 27)."""
    async with await open_mixed(tmp_path) as m:
        c = m["c"]
        await c.move_to(700.0, wait=True, timeout=10)
        with pytest.raises(LimitError, match="outside the soft limits"):
            await c.move_by(30.0)
        await c.turn(720.0, ttl=1.0)  # 2 rev/s towards +720
        # a DMM lease moves in steps and rests between them (docs/safety.md): wait for the
        # rest at the limit's own target, not for any rest near it
        await wait_until_async(
            lambda: _stopped_near(c, 720.0, 0.5 if c.lease is None or c.lease.at_limit
                                  else 0.0),
            timeout=10, what="the lease brings c to rest at its limit")
        position = await c.position()
        assert 719.5 <= position <= 720.0 + 0.1, position  # at the limit, not past it
        sent: list[object] = []
        await c.core().add_trace(lambda d, data, t: sent.append(data)
                                 if d is Direction.TX else None)
        await c.stop()
        sent.clear()
        with pytest.raises(LimitError, match="at soft limit"):
            await c.turn(10.0)
        assert all(type(x).__name__ == "ReadRequest" for x in sent), \
            f"a refused jog at the limit only reads: {sent}"
        assert abs(await c.position() - position) < 0.1  # it moved 0 counts
        await c.turn(-10.0)  # away from the limit is allowed
        await c.stop()


async def _stopped_near(axis: object, limit: float, within: float = 0.5) -> bool:
    from servobus.machine import AsyncMachineAxis

    assert isinstance(axis, AsyncMachineAxis)
    return abs(await axis.position() - limit) < within and abs(await axis.speed()) < 1.0


async def _stopped_past(axis: object, limit: float) -> bool:
    from servobus.machine import AsyncMachineAxis

    assert isinstance(axis, AsyncMachineAxis)
    return await axis.position() >= limit and abs(await axis.speed()) < 1.0


async def test_axes_on_one_url_share_one_link(tmp_path: Path) -> None:
    async with await open_mixed(tmp_path) as m:
        x, y, c = (m[n].core() for n in ("x", "y", "c"))
        assert [link.url for link in m.links] == ["sim://dyn232?fast=1", "sim://easycan?fast=1"]
        assert getattr(x, "client", None) is getattr(y, "client", 1)
        assert getattr(x, "client", None) is not getattr(c, "client", None)
        await m["y"].move_to(5.0, wait=True, timeout=10)  # a second drive on the one line
        assert abs(await m["y"].position() - 5.0) < 0.01
        assert abs(await m["x"].position()) < 0.01


async def test_stop_all_stops_every_axis(tmp_path: Path) -> None:
    async with await open_mixed(tmp_path) as m:
        await m["x"].turn(20.0, ttl=1.0)
        await m["y"].turn(-20.0, ttl=1.0)
        await m["c"].turn(90.0, ttl=1.0)
        await wait_until_async(lambda: _all_moving(m), timeout=10, what="all moving")
        assert await m.stop_all() == {"x": None, "y": None, "c": None}
        await wait_until_async(lambda: _all_still(m), timeout=10, what="all stopped")


async def _all_moving(m: AsyncMachine) -> bool:
    return all([abs(await a.speed()) > 0 for a in m.axes.values()])


async def _all_still(m: AsyncMachine) -> bool:
    return all([abs(await a.speed()) < 1e-9 for a in m.axes.values()])


SYNC = """\
[axes.a]
url = "sim://dyncan?fast=1"
id = 1
unit = "rev"
[axes.b]
url = "sim://dyncan?fast=1"
id = 2
unit = "deg"
[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
[axes.d]
url = "sim://easycan?fast=1"
id = 2
unit = "mm"
per_rev = 10.0
gear = 2.0
direction = -1
[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
"""


async def test_move_together_uses_the_synchronised_start_where_the_bus_has_one(
        tmp_path: Path) -> None:
    async with await open_machine_async(write_machine(tmp_path, SYNC)) as m:
        targets = {"a": 2.0, "b": 360.0, "c": 90.0, "d": 5.0, "x": 10.0}
        report = await m.move_together(targets, wait=True, timeout=10)
        assert sorted(map(sorted, report.groups)) == [["a", "b"], ["c", "d"]]
        assert not report.synchronised
        assert report.starts["a"] == report.starts["b"]  # one trigger, one moment
        assert report.starts["c"] == report.starts["d"]
        assert report.skew_s == max(report.starts.values()) - min(report.starts.values())
        assert m["d"].to_counts(5.0) == -32768  # 5 mm / 10 mm x 2 x 32,768, reversed
        for name, target in targets.items():
            assert abs(await m[name].position() - target) < 0.5, name


async def test_move_together_on_one_bus_is_one_trigger(tmp_path: Path) -> None:
    text = SYNC.split("[axes.c]")[0]
    async with await open_machine_async(write_machine(tmp_path, text)) as m:
        report = await m.move_together({"a": -1.0, "b": 90.0}, wait=True, timeout=10)
        assert report.synchronised and report.skew_s == 0.0


async def test_a_link_that_cannot_open_is_one_error_naming_axis_and_url(
        tmp_path: Path) -> None:
    registry.register("flaky", "machine_rig:flaky_open")
    machine_rig.FLAKY.update(down=True, attempts=0)
    text = machine_rig.MIXED + '\n[axes.z]\nurl = "flaky://line"\nid = 3\nunit = "rev"\n'
    path = write_machine(tmp_path, text)
    with pytest.raises(MachineLinkError, match=r"axis z: cannot open flaky://line") as info:
        await open_machine_async(path)
    assert "\n" not in str(info.value)


async def test_retry_starts_offline_and_comes_online(tmp_path: Path) -> None:
    registry.register("flaky", "machine_rig:flaky_open")
    machine_rig.FLAKY.update(down=True, attempts=0)
    text = machine_rig.MIXED + '\n[axes.z]\nurl = "flaky://line"\nid = 3\nunit = "rev"\n'
    async with await open_machine_async(write_machine(tmp_path, text), retry=True) as m:
        z = m["z"]
        assert not z.online and z.axis is None
        assert isinstance(z.last_error, MachineLinkError)
        with pytest.raises(MachineLinkError, match=r"axis z is offline \(flaky://line\)"):
            await z.position()
        result = await m.stop_all()
        assert result["x"] is None and isinstance(result["z"], MachineLinkError)
        assert m["x"].online
        machine_rig.FLAKY["down"] = False
        await wait_until_async(lambda: _online(z), timeout=10, what="z back online")
        assert z.protocol == "dyn232" and z.drive_id == 3
        assert await z.position() == 0.0


async def _online(axis: object) -> bool:
    await asyncio.sleep(0)  # a coroutine predicate for wait_until_async: one yield, no wait
    return bool(getattr(axis, "online", False))


def test_sync_facade_and_package_exports(tmp_path: Path) -> None:
    with servobus.open_machine(write_machine(tmp_path)) as m:
        assert list(m.axes) == ["x", "y", "c"]
        m["x"].move_to(12.5, wait=True, timeout=10)
        assert abs(m["x"].position() - 12.5) < 0.01
        axis = m["x"].axis
        assert axis is not None and axis.drive_id == 1
        with pytest.raises(ArgumentRangeError, match=r"no axis 'q'.*axes: x, y, c"):
            m["q"]
        with pytest.raises(LimitError):
            m["x"].move_to(-11)
        report = m.move_together({"x": 0.0, "c": 10.0}, wait=True, timeout=10)
        assert report.skew_s >= 0.0
        assert m.stop_all() == {"x": None, "y": None, "c": None}


def test_builtin_machine_mixes_vendors() -> None:
    with servobus.open_machine(None) as m:
        assert m.path is None
        assert {(a.name, a.unit, a.protocol) for a in m.axes.values()} == {
            ("x", "mm", "dyn232"), ("y", "mm", "dyn232"), ("c", "deg", "easycan")}


async def test_the_guard_stops_motion_started_around_the_machine(tmp_path: Path) -> None:
    text = ('[axes.c]\nurl = "sim://easycan?fast=1"\nid = 1\nunit = "deg"\n'
            "limits = [-10.0, 90.0]\n")
    async with await open_machine_async(write_machine(tmp_path, text)) as m:
        c = m["c"]
        m.guard_limits(period=0.01)
        await c.core().turn(60)  # the Axis itself, as a GUI jog does: the machine not asked
        await wait_until_async(lambda: _stopped_past(c, 90.0), timeout=10,
                               what="the guard stops c past its limit")
        assert await c.position() < 150.0


async def test_origin_rules_at_start_up(tmp_path: Path,
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    from servobus.machine import AsyncMachineAxis

    calls: list[str] = []
    real = AsyncMachineAxis.set_origin

    async def counted(self: AsyncMachineAxis) -> None:
        calls.append(self.name)
        await real(self)

    monkeypatch.setattr(AsyncMachineAxis, "set_origin", counted)
    text = ('[axes.c]\nurl = "sim://easycan?fast=1"\nid = 1\nunit = "deg"\n'
            'origin = "set"\n[axes.x]\nurl = "sim://dyn232?fast=1"\nunit = "rev"\n')
    async with await open_machine_async(write_machine(tmp_path, text)) as m:
        assert calls == ["c"]  # x has no origin rule
        assert await m["c"].position() == 0.0
    path = write_machine(tmp_path, text.replace('"set"', '"home"'))
    with pytest.raises(NotSupported, match=r"m\.toml: axis c: origin: .* homes only by itself "
                       r"at power-on.*use origin = \"set\"") as info:
        await open_machine_async(path)
    assert "\n" not in str(info.value)
