"""A machine: named axes across links and vendors, in user units, inside soft limits.

``open_machine(path)`` (sync) and ``open_machine_async(path)`` read a TOML machine file
(docs/machine.md); ``None`` opens the built-in virtual machine (servobus.machine.builtin).
"""

from servobus.machine.axis import AsyncMachineAxis
from servobus.machine.config import (
    AxisSpec,
    MachineSpec,
    load_machine_file,
    parse_machine,
    url_spec,
)
from servobus.machine.machine import (
    AsyncMachine,
    TogetherReport,
    open_machine_async,
    open_url_machine_async,
)
from servobus.machine.sync import Machine, MachineAxis, open_machine, open_url_machine
from servobus.machine.units import Scale, parse_quantity

__all__ = [
    "AsyncMachine",
    "AsyncMachineAxis",
    "AxisSpec",
    "Machine",
    "MachineAxis",
    "MachineSpec",
    "Scale",
    "TogetherReport",
    "load_machine_file",
    "open_machine",
    "open_machine_async",
    "open_url_machine",
    "open_url_machine_async",
    "parse_machine",
    "parse_quantity",
    "url_spec",
]
