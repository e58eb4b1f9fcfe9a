"""YzaimAxis, the YZ-AIM mapping both wires share, on a register dict instead of a wire:
what is written for each Axis call, the remembered target, the cruise speed and ping."""

from __future__ import annotations

import pytest

from servobus.errors import (
    ArgumentRangeError,
    DriveError,
    DriveTimeout,
    FramingError,
    MotionRefused,
)
from servobus.families.yzaim import registers as Y
from servobus.families.yzaim.axis import FALLBACK_CRUISE_RPM, YzaimAxis
from servobus.protocols.easycan.axis import EasyCanAxis
from servobus.protocols.modbus.axis import ModbusAxis

pytestmark = pytest.mark.timeout(10)


class Wire:
    """A register map and the log of what was written."""

    def __init__(self) -> None:
        self.values: dict[str, int] = {**Y.defaults(), "absolute_position": 500}
        self.writes: list[tuple[str, int]] = []
        self.probe_error: BaseException | None = None
        self.closed = 0

    def add_trace(self, hook: object) -> None:
        pass

    async def close(self) -> None:
        self.closed += 1


class FakeAxis(YzaimAxis[Wire]):
    protocol_name = "fake"
    reachable_params = ("target_speed", "special_function", "gear_numerator")
    reply_position: int | None = None  # what _write_increment's reply carries, if it does

    def _check_id(self, drive_id: int) -> int:
        if not 1 <= drive_id <= 254:
            raise ArgumentRangeError(f"address {drive_id}")
        return drive_id

    async def _read(self, name: str) -> int:
        return self.client.values.get(name, 0)

    async def _read_words(self, names: tuple[str, ...]) -> tuple[int, ...]:
        return tuple(Y.BY_NAME[n].word(self.client.values.get(n, 0)) for n in names)

    async def _write(self, name: str, value: int) -> None:
        self.client.writes.append((name, int(value)))
        self.client.values[name] = int(value)

    async def _probe(self, timeout: float) -> None:
        if self.client.probe_error is not None:
            raise self.client.probe_error

    async def emergency_stop(self) -> None:
        self._target = None

    async def set_origin(self) -> None:
        self._target = None


async def test_a_move_to_zero_sends_one_and_the_target_is_remembered() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 3)
    await axis.move_to(0)
    assert wire.writes == [("special_function", 0), ("absolute_position", 1)]
    wire.values["absolute_position"] = 4
    assert (await axis.status()).in_position  # 4 counts from 0: inside +-10 (5.4a)
    wire.values["absolute_position"] = 11
    assert not (await axis.status()).in_position
    wire.writes.clear()
    await axis.move_by(0)  # 0 would stop the motor at gear numerator 0: nothing sent
    await axis.move_by(100)  # position mode is known now: the increment alone
    assert wire.writes == [("incremental_position", 100)]
    assert axis._target == 100


async def test_a_relative_move_without_a_target_starts_from_the_position_or_the_reply() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 1)
    await axis.move_by(-20)
    assert axis._target == 480  # read 500 before the write
    other = FakeAxis(Wire(), 1)

    async def reply_carries_position(distance: int, *, need_start: bool) -> int | None:
        await other._write("incremental_position", distance)
        return 7

    other._write_increment = reply_carries_position  # type: ignore[method-assign]
    await other.move_by(5)
    assert other._target == 12


async def test_turn_then_a_move_restores_the_cruise_speed() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 1)
    wire.values["target_speed"] = 1200
    await axis.turn(-300)
    assert wire.writes == [("dir_polarity", 1), ("target_speed", 300),
                           ("special_function", Y.SpecialFunction.SPEED_MODE)]
    wire.writes.clear()
    await axis.move_to(50)
    assert wire.writes == [("special_function", 0), ("target_speed", 1200),
                           ("absolute_position", 50)]
    with pytest.raises(ArgumentRangeError, match="target_speed"):
        await axis.turn(Y.BY_NAME["target_speed"].maximum + 1)


async def test_current_takes_the_sign_of_the_output_duty() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 1)
    wire.values.update(system_current=3000, output_pwm=-5)
    assert await axis.current() == -1.5
    wire.values["output_pwm"] = 5
    assert await axis.current() == 1.5


@pytest.mark.parametrize(("error", "answered"), [
    (None, True), (DriveTimeout("silent"), False), (DriveError("error reply", code=5), True),
    (FramingError("garbled"), True)])
async def test_ping_any_reply_answers(error: BaseException | None, answered: bool) -> None:
    wire = Wire()
    wire.probe_error = error
    assert await FakeAxis(wire, 1).ping() is answered


async def test_siblings_share_the_client_and_only_the_owner_closes_it() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 1)
    sibling = await axis.sibling(2)
    assert (sibling.client, sibling.drive_id, repr(sibling)) == (wire, 2, "<FakeAxis motor 2>")
    await sibling.close()
    assert wire.closed == 0
    await axis.close()
    assert wire.closed == 1
    with pytest.raises(ArgumentRangeError):
        FakeAxis(wire, 0)


def test_both_yzaim_wires_share_the_mapping() -> None:
    """The Axis mapping stays in YzaimAxis: the wires add only their own means."""
    shared = {"turn", "status", "position", "read_param", "write_param", "assign_id", "ping",
              "_send_move_to", "_send_move_by", "sibling", "close"}
    for cls in (EasyCanAxis, ModbusAxis):
        assert issubclass(cls, YzaimAxis)
        assert not shared & set(vars(cls)), cls


# ------------------------------------------------------------- issue 28: stops and refusals
async def test_a_stop_leaves_position_mode_at_the_cruise_speed_it_replaced() -> None:
    """turn(0) ramps down in speed mode, then returns to position mode and writes the cruise
    speed back on the drive: the next program's move does not run at 0 rpm."""
    wire = Wire()
    axis = FakeAxis(wire, 1)
    wire.values["target_speed"] = 1200
    await axis.turn(300)
    wire.writes.clear()
    await axis.stop()
    assert wire.writes == [("target_speed", 0), ("special_function", 0),
                           ("target_speed", 1200)]
    assert (wire.values["special_function"], wire.values["target_speed"]) == (0, 1200)
    wire.writes.clear()
    await axis.move_to(50)  # position mode and cruise known: the move alone
    assert wire.writes == [("absolute_position", 50)]


async def test_a_stop_of_a_position_move_passes_through_speed_mode_and_back() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 1)
    await axis.move_to(5000)
    wire.writes.clear()
    await axis.stop()
    assert wire.writes == [("target_speed", 0), ("special_function", 3),
                           ("special_function", 0), ("target_speed", 1000)]


async def test_a_stop_by_another_program_finding_speed_mode_restores_the_fallback() -> None:
    """A new program finds the motor turning in speed mode: the cruise speed the other one
    replaced is lost; the stop leaves the table's power-on cruise speed, never 0."""
    wire = Wire()
    wire.values.update(special_function=3, target_speed=0)  # left stopped in speed mode
    axis = FakeAxis(wire, 1)
    await axis.stop()
    assert (wire.values["special_function"], wire.values["target_speed"]) == (
        0, FALLBACK_CRUISE_RPM)
    wire.values.update(special_function=3, target_speed=700)  # left turning at 700 rpm
    fresh = FakeAxis(wire, 1)
    wire.writes.clear()
    await fresh.move_to(10)
    assert wire.writes == [("special_function", 0), ("target_speed", FALLBACK_CRUISE_RPM),
                           ("absolute_position", 10)]


@pytest.mark.parametrize("relative", [False, True])
async def test_a_move_at_cruise_speed_zero_is_refused_before_any_write(relative: bool) -> None:
    wire = Wire()
    wire.values["target_speed"] = 0
    axis = FakeAxis(wire, 1)
    with pytest.raises(MotionRefused, match=r"cruise speed .* is 0 rpm"):
        await (axis.move_by(100) if relative else axis.move_to(100))
    assert wire.writes == []
    await axis.write_param("target_speed", 500)  # position mode: a cruise speed, allowed
    await (axis.move_by(100) if relative else axis.move_to(100))
    assert wire.writes[-1][0] == ("incremental_position" if relative else "absolute_position")


async def test_speed_mode_register_writes_are_refused_unless_the_axis_is_continuous() -> None:
    wire = Wire()
    axis = FakeAxis(wire, 1)
    with pytest.raises(MotionRefused, match="not continuous"):
        await axis.write_param("special_function", Y.SpecialFunction.SPEED_MODE)
    with pytest.raises(MotionRefused):
        await axis.write_params({"target_speed": 10, "special_function": 3})
    assert wire.writes == []
    wire.values["special_function"] = 3  # another program left it in speed mode at 0 rpm
    wire.values["target_speed"] = 0
    with pytest.raises(MotionRefused, match="target_speed = 1000 rpm in speed mode"):
        await axis.write_param("target_speed", 1000)  # 0x19 read once: speed mode
    with pytest.raises(MotionRefused):
        await axis.write_param("target_speed", 1000)  # known now: not even a read
    await axis.write_param("target_speed", 0)  # slowing down is no open-ended motion
    assert wire.writes == [("target_speed", 0)]
    spindle = FakeAxis(Wire(), 2)
    spindle.continuous = True
    await spindle.write_param("special_function", 3)
    await spindle.write_param("target_speed", 600)
    assert spindle.client.writes == [("special_function", 3), ("target_speed", 600)]
