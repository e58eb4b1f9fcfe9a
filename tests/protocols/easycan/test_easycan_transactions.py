"""The EasyCan client on the shared TransactionManager (issue 9), on a scripted CAN port.

The manager's own rules are tested on a scripted medium (test_link_transaction.py); here:
the client exposes the one manager and stats class, applies EasyCan's rule table (which
commands are re-sent, which reply answers which request, lanes per motor and for cache
writes, the EEPROM-backed save flag), measures deadlines from when the frame left, and
ends waiting calls at once when the bus dies.
"""

from __future__ import annotations

import asyncio
import math

import pytest
from can_rig import Answer, Script, ScriptedCanPort

from servobus.axis import connect
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
    EepromGuardError,
)
from servobus.families.yzaim import registers as Y
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.transaction import TransactionStats
from servobus.protocols.dyncan import commands as dyncan_cmds
from servobus.protocols.easycan import codec
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.protocols.easycan.functions import ErrorCode, Function
from servobus.protocols.easycan.messages import (
    ErrorReply,
    PositionCacheWrite,
    ReadReply,
    ReadRequest,
    Reply,
    Request,
    WriteReply,
)
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.transport.base import Direction

pytestmark = pytest.mark.timeout(30)

def motors(*addresses: int) -> Script:
    """Answer like virtual YZ-AIM motors (at once)."""
    network = EasyCanNetwork([YzaimMotor(a) for a in addresses])
    return lambda arbitration_id, data: network.handle_raw(arbitration_id, data)


def requests(port: ScriptedCanPort) -> list[Request]:
    """What the client sent, decoded."""
    return [codec.decode_request(*frame) for frame in port.sent]


def answer(port: ScriptedCanPort, reply: Reply) -> None:
    """``reply`` arrives from the bus now."""
    port.push(*codec.encode(reply))


async def until_sent(port: ScriptedCanPort, n: int) -> None:
    while len(port.sent) < n:
        await asyncio.sleep(0)  # polling helper: yield to the tasks that send (no timer)


# ------------------------------------------------------------------ the one manager
async def test_the_client_exposes_the_shared_manager_and_its_stats() -> None:
    client = AsyncEasyCanClient(ScriptedCanPort(motors(1)))
    assert type(client.stats) is TransactionStats
    assert client.stats is client.transactions.stats
    assert client.late_replies is client.transactions.late_replies
    assert client.guard is client.transactions.guard
    assert await client.read(cmds.make_read(1, "target_speed")) == 1000
    assert client.stats.sent == client.stats.replies == 1
    await client.close()
    assert client.closed
    with pytest.raises(ConnectionLost):
        await client.read(cmds.make_read(1, "target_speed"))


async def test_a_command_of_another_protocol_is_refused_before_sending() -> None:
    port = ScriptedCanPort(motors(1))
    client = AsyncEasyCanClient(port)
    foreign = dyncan_cmds.make_read_status(1)
    with pytest.raises(ArgumentRangeError, match="not an EasyCan command"):
        await client.execute(foreign)  # type: ignore[arg-type]
    with pytest.raises(ArgumentRangeError, match="not an EasyCan command"):
        await client.send_only(foreign)  # type: ignore[arg-type]
    assert port.sent == [] and client.stats.sent == 0
    await client.close()


async def test_options_and_per_call_knobs_are_checked_before_sending() -> None:
    port = ScriptedCanPort(motors(1))
    for bad in ({"timeout": 0}, {"timeout": math.nan}, {"retries": -1}, {"retries": 1.5},
                {"late_reply_s": -0.1}, {"eeprom_guard": "yes"}):
        with pytest.raises(ArgumentRangeError):
            AsyncEasyCanClient(port, **bad)
    client = AsyncEasyCanClient(port)
    read = cmds.make_read(1, "target_speed")
    for knobs in ({"retries": -1}, {"retries": 1.5}, {"timeout": 0}, {"timeout": math.inf}):
        with pytest.raises(ArgumentRangeError):
            await client.execute(read, **knobs)
    assert port.sent == []
    await client.close()


@pytest.mark.parametrize("query", ["retries=-1", "timeout=0", "late_reply_s=-1"])
def test_a_bad_client_option_in_the_url_is_refused(query: str) -> None:
    with pytest.raises(ArgumentRangeError), connect(f"sim://easycan?fast=1&{query}"):
        pass


# ------------------------------------------------------------------ what is re-sent
@pytest.mark.parametrize(("command", "attempts"), [
    (cmds.make_read(1, "absolute_position"), 3),
    (cmds.make_read_registers(1, ("output_enable", "alarm_code")), 3),
    (cmds.make_write(1, "target_speed", 500), 3),  # a setting: the same value again
    (cmds.make_move_absolute(1, 5000), 1),
    (cmds.make_move_relative(1, -5000), 1),
    (cmds.make_write(1, "save_flag", 1), 1),
    (cmds.make_write(1, "sync_control", 1), 1),
    (cmds.make_emergency_stop(1), 1),
    (cmds.make_cache(1, 100, reply=True), 1),
], ids=lambda v: getattr(v, "what", str(v)))
async def test_reads_and_settings_are_retried_the_rest_is_sent_once(
        command: cmds.EasyCanCommand, attempts: int) -> None:
    port = ScriptedCanPort()  # a motor that never answers
    client = AsyncEasyCanClient(port, timeout=0.005, late_reply_s=0)
    with pytest.raises(DriveTimeout) as info:
        await client.execute(command)
    assert requests(port) == [command.request] * attempts
    assert client.stats.timeouts == attempts and client.stats.retries == attempts - 1
    assert ("not re-sent" in str(info.value)) == (attempts == 1)
    assert f"motor 1 to {command.what}" in str(info.value)
    await client.close()


async def test_an_error_reply_ends_the_call_without_a_resend() -> None:
    def refuse(arbitration_id: int, data: bytes) -> list[Answer]:
        return [codec.encode(ErrorReply(1, Function.READ, ErrorCode.ILLEGAL_ADDRESS))]

    port = ScriptedCanPort(refuse)
    client = AsyncEasyCanClient(port, retries=2)
    with pytest.raises(DriveError) as info:
        await client.read(cmds.make_read(1, "max_current"))
    assert info.value.code == 0x02 and info.value.drive_id == 1
    assert "max_current (0x1D)" in str(info.value)
    assert len(port.sent) == 1
    assert client.stats.error_replies == 1
    assert client.stats.retries == client.stats.timeouts == 0
    await client.close()


# ------------------------------------------------------------------ which reply answers
async def test_a_reply_of_another_register_is_not_taken_for_the_answer() -> None:
    port = ScriptedCanPort()
    client = AsyncEasyCanClient(port)
    call = asyncio.create_task(client.read(cmds.make_read(1, "target_speed")))
    await until_sent(port, 1)
    answer(port, ReadReply(1, 0x03, (7,)))  # another host's read of motor 1 (acceleration)
    answer(port, ReadReply(1, 0x02, (2, 0)))  # the right register, but two words
    answer(port, ReadReply(1, 0x02, (1234,)))
    assert await call == 1234
    assert client.stats.unmatched == 2 and client.stats.replies == 1
    await client.close()


async def test_two_motors_wait_at_once_one_motor_one_request_at_a_time() -> None:
    port = ScriptedCanPort()
    client = AsyncEasyCanClient(port)
    one = asyncio.create_task(client.read(cmds.make_read(1, "target_speed")))
    two = asyncio.create_task(client.read(cmds.make_read(2, "target_speed")))
    again = asyncio.create_task(client.read(cmds.make_read(1, "acceleration")))
    await until_sent(port, 2)
    for _ in range(5):  # "not sent" has no event: five loop passes to send it wrongly
        await asyncio.sleep(0)  # see above
    assert [r.slave for r in requests(port)] == [1, 2]  # motor 1's second read waits its turn
    answer(port, ReadReply(2, 0x02, (222,)))  # answered in the other order
    answer(port, ReadReply(1, 0x02, (111,)))
    assert await two == 222 and await one == 111
    await until_sent(port, 3)
    assert requests(port)[2] == ReadRequest(1, 0x03, 1)
    answer(port, ReadReply(1, 0x03, (333,)))
    assert await again == 333
    await client.close()


async def test_a_too_fast_error_answers_the_cache_write_not_a_register_write() -> None:
    port = ScriptedCanPort()
    client = AsyncEasyCanClient(port)
    cache = asyncio.create_task(client.position_write(cmds.make_cache(1, 100, reply=True)))
    write = asyncio.create_task(client.execute(cmds.make_write(1, "target_speed", 500)))
    await until_sent(port, 2)  # two lanes: the cache write does not wait for motor 1's
    assert isinstance(requests(port)[0], PositionCacheWrite)
    answer(port, ErrorReply(1, Function.WRITE, ErrorCode.INTERPOLATION_TOO_FAST))
    answer(port, WriteReply(1, 0x02, (500,)))
    with pytest.raises(DriveError) as info:
        await cache
    assert info.value.code == 0x05 and "position_cache (0x1A)" in str(info.value)
    assert isinstance(await write, WriteReply)
    await client.close()


# ------------------------------------------------------------------ deadlines, guard, links
async def test_the_deadline_runs_from_when_the_frame_left() -> None:
    # a send that takes longer than the deadline (a full adapter queue, socketcand over a
    # slow link), answered at once after it: the old client started its timer before
    # sending, so its first attempt timed out and the read was sent twice (a move, never
    # re-sent, failed)
    port = ScriptedCanPort(motors(1), send_s=0.08)
    client = AsyncEasyCanClient(port, timeout=0.05)
    assert await client.read(cmds.make_read(1, "acceleration")) == 10000
    assert client.stats.timeouts == 0 and len(port.sent) == 1
    await client.close()


async def test_the_save_flag_passes_the_eeprom_guard() -> None:
    port = ScriptedCanPort(motors(1))
    client = AsyncEasyCanClient(port, eeprom_guard=EepromGuard(warn_per_window=100,
                                                               max_per_window=2))
    save = cmds.make_write(1, "save_flag", Y.SaveFlag.SAVE)
    await client.execute(save)
    await client.execute(cmds.make_write(1, "save_flag", 0))  # saves nothing: not counted
    await client.execute(cmds.make_write(1, "target_speed", 900))  # RAM
    await client.execute(save)
    sent = len(port.sent)
    with pytest.raises(EepromGuardError, match="save_flag"):
        await client.execute(save)
    assert len(port.sent) == sent  # refused before sending
    assert client.guard.totals == {(1, "save_flag"): 2}
    await client.close()


async def test_a_dying_bus_ends_the_waiting_read_at_once() -> None:
    port = ScriptedCanPort()
    client = AsyncEasyCanClient(port, timeout=5.0)
    loop = asyncio.get_running_loop()
    call = asyncio.create_task(client.read(cmds.make_read(1, "target_speed")))
    await until_sent(port, 1)
    t = loop.time()
    await port.close()
    with pytest.raises(ConnectionLost, match="motor 1"):
        await call
    assert loop.time() - t < 1.0
    with pytest.raises(ConnectionLost):
        await client.execute(cmds.make_write(1, "target_speed", 1))
    with pytest.raises(ConnectionLost):
        await client.send_only(cmds.make_cache(1, 0))
    assert len(port.sent) == 1
    await client.close()


async def test_a_timeout_is_traced_and_a_late_reply_dropped() -> None:
    port = ScriptedCanPort()
    client = AsyncEasyCanClient(port, timeout=0.01, retries=0)
    seen: list[tuple[Direction, object]] = []
    client.add_trace(lambda d, item, t: seen.append((d, item)))
    read = cmds.make_read(1, "target_speed")
    with pytest.raises(DriveTimeout):
        await client.read(read)
    assert seen[0] == (Direction.TX, read.request)
    assert seen[1][0] is Direction.RX and isinstance(seen[1][1], DriveTimeout)
    answer(port, ReadReply(1, 0x02, (1000,)))  # the late one: owed, dropped
    assert client.stats.late_replies == 1 and client.stats.unmatched == 0
    answer(port, ReadReply(1, 0x02, (1000,)))  # nothing owed any more: a stray
    assert client.stats.unmatched == 1
    await client.close()
