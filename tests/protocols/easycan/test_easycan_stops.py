"""Two stops of one YZ-AIM motor at once (servobus hal's sync group and its SIGTERM both
stopping it): the stop sequence (0x02 = 0, 0x19 = 3, 0x19 = 0, 0x02 = cruise) runs one at
a time, so the motor is never in speed mode at a speed above 0 (servobus.families.yzaim.axis,
"One mode sequence at a time")."""

from __future__ import annotations

import asyncio

from can_rig import Answer, ScriptedCanPort

from servobus.protocols.easycan import codec
from servobus.protocols.easycan.axis import EasyCanAxis
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.protocols.easycan.messages import WriteRequest
from servobus.sim.yzaim.motor import YzaimMotor

SPECIAL_FUNCTION = 0x19
POSITION_MODE = 0


async def test_a_second_stop_while_the_first_ends_never_turns_the_motor() -> None:
    motor = YzaimMotor(1)  # no clock: it moves only as the registers say, never by itself
    network = EasyCanNetwork([motor])
    turning: list[dict[str, int]] = []  # registers whenever speed mode ran at > 0 rpm
    second: list[asyncio.Task[None]] = []
    axis: EasyCanAxis | None = None
    stopping = False

    def answer(arbitration_id: int, data: bytes) -> list[Answer]:
        request = codec.decode_request(arbitration_id, data)
        if (isinstance(request, WriteRequest) and request.address == SPECIAL_FUNCTION
                and request.values == (POSITION_MODE,) and stopping and not second):
            # the first stop leaves speed mode now; a second stop starts before its reply
            # comes back (the exact moment the HAL component's two stops met in CI)
            assert axis is not None
            second.append(asyncio.get_running_loop().create_task(axis.stop()))
        replies: list[Answer] = list(network.handle_raw(arbitration_id, data))
        registers = motor.registers()
        if motor.speed_mode and registers["target_speed"] > 0:
            turning.append(registers)
        return replies

    client = AsyncEasyCanClient(ScriptedCanPort(answer))
    axis = EasyCanAxis(client, 1)
    try:
        await axis.enable()
        await axis.move_to(1000)  # the cruise speed (0x02) is known and above 0: 1000 rpm
        stopping = True
        await axis.stop()
        assert second, "the second stop did not start while the first ended"
        await second[0]
        assert turning == [], "speed mode at the cruise speed: the motor turned after a stop"
        registers = motor.registers()
        assert registers["special_function"] == POSITION_MODE
        assert registers["target_speed"] == 1000  # ready for the next move at its cruise
    finally:
        await axis.close()
