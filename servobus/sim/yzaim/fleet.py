"""Build the virtual YZ-AIM motors a server or an in-process ``sim://`` bus holds (any protocol)."""

from __future__ import annotations

from collections.abc import Sequence

from servobus.families.yzaim import registers as yzaim
from servobus.sim.core.ids import parse_ids
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.sim.yzaim.store import YzaimStore

FACTORY_ADDRESS = 1  # a motor's address when none is asked for (decision)
_ADDRESS = yzaim.BY_NAME["device_address"]


def parse_addresses(text: str) -> tuple[int, ...]:
    """``"1,2,3"`` -> (1, 2, 3): device addresses 1..254 (register 0x15's range)."""
    return parse_ids(text, min_id=_ADDRESS.minimum, max_id=_ADDRESS.maximum)


def make_motors(addresses: Sequence[int], *, state: str | None = None,
                model: str = yzaim.DEFAULT_MODEL) -> list[YzaimMotor]:
    """One motor per address; with ``state`` each keeps its EEPROM under key str(address)."""
    yzaim.model(model)  # ArgumentRangeError naming the known models
    return [YzaimMotor(a, model=model,
                       store=YzaimStore(state, key=str(a)) if state else None)
            for a in addresses]


def record_positions(motors: Sequence[YzaimMotor]) -> None:
    """The simulator stops: each motor records its position as at a power-off (1:
    "communication mode: power-off record position"), kept in its state file if it has one,
    so a multi-turn position survives a restart of ``sim easycan`` / ``sim modbus``."""
    for motor in motors:
        motor.store.record_position(motor.position)
