"""What ``params``/``set`` reach over Modbus RTU: every parameter of the YZ-AIM family (the
serial port reads and writes every register, manual section 6)."""

from __future__ import annotations

from servobus.families.yzaim.family import PARAM_NAMES

REACHABLE_PARAMS: tuple[str, ...] = PARAM_NAMES
