"""EasyCan client and axis against virtual YZ-AIM motors and a scripted bus.

The scripted bus (can_rig) is read through ``recv`` here (``push_mode=False``: a port
without ``set_receiver``), the path test_easycan_transactions.py does not take.

Golden frames: the manual's 5.4a examples (speed 1000 + acceleration 10000 in one write,
absolute position 2 turns, incremental -32768) as the client sends them.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import pytest
from can_rig import Answer, Script, ScriptedCanPort
from rig import wait_until_async

from servobus.errors import ArgumentRangeError, ConnectionLost, DriveError, DriveTimeout
from servobus.families.yzaim import registers as Y
from servobus.protocols.easycan import codec
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.axis import EasyCanAxis
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.easycan.commands import EasyCanCommand
from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.protocols.easycan.messages import ReadReply, ReadRequest, WriteRequest
from servobus.protocols.easycan.server import serve
from servobus.sim.wall_clock import RealtimeClock
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.transport.base import Direction
from servobus.transport.can_bus import AsyncCanBus

pytestmark = pytest.mark.timeout(60)
_channels = itertools.count()


# ------------------------------------------------------------------ rigs
@dataclass
class Rig:
    network: EasyCanNetwork
    client: AsyncEasyCanClient

    def axis(self, address: int) -> EasyCanAxis:
        return EasyCanAxis(self.client, address, owns_client=False)


@asynccontextmanager
async def rig(*addresses: int, timeout: float | None = None) -> AsyncIterator[Rig]:
    """Virtual motors on a python-can virtual bus, in wall-clock time."""
    spec = f"virtual:servobus-easycan-test-{next(_channels)}"
    network = EasyCanNetwork([YzaimMotor(a) for a in addresses])
    node_port = await AsyncCanBus.open(spec)
    stop = asyncio.Event()
    server = asyncio.create_task(serve(network, node_port, clock=RealtimeClock(network.motors),
                                       stop=stop))
    client = AsyncEasyCanClient(await AsyncCanBus.open(spec), timeout=timeout)
    try:
        yield Rig(network, client)
    finally:
        await client.close()
        stop.set()
        await server
        await node_port.close()


def motor_answers(motor: YzaimMotor, delay: float = 0.0,
                  drop: Callable[[int], bool] = lambda n: False) -> Script:
    """Answer like a motor; ``drop(n)`` (n = request number) swallows replies."""
    network = EasyCanNetwork([motor])
    counter = itertools.count()

    def answer(arbitration_id: int, data: bytes) -> list[Answer]:
        out = network.handle_raw(arbitration_id, data)
        if drop(next(counter)):
            return []
        return [(i, d, delay) for i, d in out]

    return answer


# ------------------------------------------------------------------ golden frames
async def test_the_manuals_frames_as_the_client_sends_them() -> None:
    motor = YzaimMotor(1)
    bus = ScriptedCanPort(motor_answers(motor), push_mode=False)
    client = AsyncEasyCanClient(bus)
    # 5.4a: FF 06 02 02 E8 03 10 27 (speed 1000 and acceleration 10000 in one frame)
    both = EasyCanCommand(WriteRequest(1, 0x02, (1000, 10000)), "write speed+accel",
                          retry_safe=True, echo=(1000, 10000))
    await client.execute(both)
    await client.execute(cmds.make_move_absolute(1, 2 * Y.COUNTS_PER_REV))
    await client.execute(cmds.make_move_relative(1, -Y.COUNTS_PER_REV))
    assert bus.sent == [
        (0x001, bytes.fromhex("FF 06 02 02 E8 03 10 27")),
        (0x001, bytes.fromhex("FF 06 16 02 00 00 01 00")),  # 5.4a: 2 turns
        (0x001, bytes.fromhex("FF 06 0C 02 00 80 FF FF")),  # 5.4a: -32768
    ]
    await client.close()


# ------------------------------------------------------------------ bad input
async def test_bad_input_is_refused_before_sending() -> None:
    bus = ScriptedCanPort(motor_answers(YzaimMotor(1)), push_mode=False)
    axis = EasyCanAxis(AsyncEasyCanClient(bus), 1)
    calls: tuple[Callable[[], Awaitable[None]], ...] = (
        lambda: axis.write_param("target_speed", 3001),
        lambda: axis.write_param("special_function", 5),  # undefined (5.2)
        lambda: axis.write_param("motor_speed", 1),  # read-only: not a parameter
        lambda: axis.move_to(1 << 31),
        lambda: axis.move_by(-(1 << 31) - 1),
        lambda: axis.turn(3001))
    for call in calls:
        with pytest.raises(ArgumentRangeError):
            await call()
    with pytest.raises(ArgumentRangeError):
        cmds.make_write(0xFF, "target_speed", 1)  # 0xFF is the host
    with pytest.raises(ArgumentRangeError):
        EasyCanAxis(axis.client, 0)
    assert bus.sent == []
    await axis.close()


# ------------------------------------------------------------------ errors, timeouts
async def test_an_error_reply_names_the_register_and_the_code() -> None:
    async with rig(1) as r:
        bad = EasyCanCommand(ReadRequest(1, 0x20, 1), "read register 0x20", retry_safe=True)
        with pytest.raises(DriveError) as info:
            await r.client.execute(bad)
        assert info.value.code == 0x02 and info.value.drive_id == 1
        assert "0x20" in str(info.value) and "illegal register address" in str(info.value)
        too_many = EasyCanCommand(ReadRequest(1, 0x02, 3), "read 3", retry_safe=True)
        with pytest.raises(DriveError) as info:
            await r.client.execute(too_many)
        assert info.value.code == 0x04 and "target_speed (0x02)" in str(info.value)
        assert await r.axis(1).read_param("target_speed") == 1000  # in step afterwards


async def test_a_write_the_motor_does_not_apply_raises() -> None:
    async with rig(1) as r:
        r.network.motors[0].write_words(0x00, [0])  # modbus_enable 0: writes not applied
        with pytest.raises(DriveError, match="did not apply"):
            await r.axis(1).write_param("target_speed", 500)
        await r.axis(1).enable()  # writes modbus_enable 1 first
        await r.axis(1).write_param("target_speed", 500)


async def test_a_lost_reply_times_out_and_the_late_one_never_answers_a_later_read() -> None:
    motor = YzaimMotor(1)
    # request 0 is answered after 80 ms (its 30 ms deadline passed); the rest at once
    network = EasyCanNetwork([motor])
    count = itertools.count()

    def answer(arbitration_id: int, data: bytes) -> list[Answer]:
        n = next(count)
        return [(i, d, 0.08 if n == 0 else 0.0) for i, d in
                network.handle_raw(arbitration_id, data)]

    bus = ScriptedCanPort(answer, push_mode=False)
    client = AsyncEasyCanClient(bus, timeout=0.03, late_reply_s=0.2)
    axis = EasyCanAxis(client, 1)
    # the first attempt's reply comes too late: the retry answers (10000)
    assert await axis.read_param("acceleration") == 10000
    assert client.stats.timeouts == 1 and client.stats.retries == 1
    motor.write_words(0x03, [20000])
    # the late reply (10000) is owed to the timed-out attempt: dropped, never this answer
    assert await axis.read_param("acceleration") == 20000
    assert client.late_replies.late == 1
    await axis.close()


async def test_reads_are_retried_moves_are_sent_once() -> None:
    bus = ScriptedCanPort(push_mode=False)  # a motor that never answers
    client = AsyncEasyCanClient(bus, timeout=0.01, late_reply_s=0)
    axis = EasyCanAxis(client, 1)
    with pytest.raises(DriveTimeout):
        await axis.position()
    assert len(bus.sent) == 3
    bus.sent.clear()
    axis._speed_mode = False  # known position mode: the move is the only frame
    axis._speed_word = 1000  # and a known cruise speed (a move at 0 rpm is refused, issue 28)
    with pytest.raises(DriveTimeout, match="not re-sent"):
        await axis.move_to(5000)
    assert [codec.decode_request(*f) for f in bus.sent] == [
        WriteRequest(1, 0x16, Y.split32(5000))]
    bus.sent.clear()
    with pytest.raises(DriveTimeout):
        await client.execute(cmds.make_write(1, "save_flag", 1))
    assert len(bus.sent) == 1
    await axis.close()


async def test_a_dead_bus_raises_connection_lost() -> None:
    async with rig(1) as r:
        await r.client.port.close()
        with pytest.raises(ConnectionLost):
            await r.axis(1).position()


# ------------------------------------------------------------------ axis behaviour
async def test_two_motors_speed_mode_and_back_to_position_mode() -> None:
    async with rig(1, 2, timeout=0.2) as r:
        one, two = r.axis(1), r.axis(2)
        await two.turn(-200)
        await asyncio.sleep(0.2)  # 200 rpm at 10000 rpm/s: 20 ms, on the virtual clock
        assert abs(await two.speed() + 200) < 2
        assert r.network.motors[1].registers()["target_speed"] == 200
        assert abs(await one.speed()) < 0.5
        await two.move_to(0, wait=True, timeout=5)  # back to position mode
        assert abs(await two.position()) <= Y.POSITION_TOLERANCE_COUNTS + 1
        regs = r.network.motors[1].registers()
        assert regs["special_function"] == 0 and regs["target_speed"] == 1000  # restored


async def test_reset_clears_a_stall_alarm() -> None:
    async with rig(1, timeout=0.2) as r:
        motor = r.network.motors[0]
        axis = r.axis(1)
        await axis.write_param("standstill_max_output", 301)  # stall alarm after 1 s
        motor.set_blocked(True)
        await axis.move_by(Y.COUNTS_PER_REV)
        async def alarmed() -> Any:  # the stall alarm trips after 1 s of the motor's time
            status = await axis.status()
            return status if status.alarm else None

        st = await wait_until_async(alarmed, timeout=20, what="the stall alarm")
        assert st.alarm_latched and st.alarm_code == 0x14 and "stall" in st.alarm_text
        motor.set_blocked(False)
        await axis.reset()
        st = await axis.status()
        assert st.enabled and not st.alarm


async def test_save_parameters_and_assign_id() -> None:
    async with rig(3) as r:
        axis = r.axis(3)
        assert await axis.read_id() == 3
        await axis.write_param("acceleration", 12345)
        await axis.save_parameters()
        assert r.network.motors[0].store.registers["acceleration"] == 12345
        await axis.assign_id(7)
        assert axis.drive_id == 7 and r.network.motors[0].store.registers[
            "device_address"] == 7
        r.network.motors[0].power_cycle()  # 5.2: the new address after power-on
        assert await axis.read_param("acceleration") == 12345


async def test_trace_sees_messages_both_ways() -> None:
    async with rig(1) as r:
        seen: list[tuple[Direction, object]] = []
        r.client.add_trace(lambda d, item, t: seen.append((d, item)))
        await r.axis(1).read_param("max_current")
        assert seen[0] == (Direction.TX, ReadRequest(1, 0x1D, 1))
        assert seen[1] == (Direction.RX, ReadReply(1, 0x1D, (5000,)))
