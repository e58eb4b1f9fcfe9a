"""DYN232M: DMM's 7-bit serial packets over RS232/RS485 (DYN2 / DC2 / DYN4), docs/dyn232.md.

URLs: ``dyn232:///dev/ttyUSB0``, ``dyn232:COM3``, ``dyn232+socket://host:port`` (any pyserial
URL after the ``+``); a bare port or pyserial URL (``/dev/ttyUSB0``, ``socket://``, ``loop://``)
is DYN232M too. ``sim://dyn232`` (aliases ``dyn2``, ``dc2``, ``dyn4``) is the in-process line.
"""

_OPEN = "servobus.protocols.dyn232.opener:open_axis"
#: pyserial's URL handlers (serial.serial_for_url) are bare serial ports: DYN232M.
PYSERIAL_SCHEMES = ("socket", "tcp", "loop", "rfc2217", "spy", "alt", "hwgrep", "cp2110")

SCHEMES: dict[str, str] = {"dyn232": _OPEN}
#: Bare serial ports and pyserial URLs: served, but not servobus's own schemes (registry).
SERIAL_SCHEMES: dict[str, str] = {"": _OPEN, **{s: _OPEN for s in PYSERIAL_SCHEMES}}
SIM: dict[str, str] = {name: "servobus.protocols.dyn232.inprocess:open_sim_axis"
                       for name in ("dyn232", "dyn2", "dc2", "dyn4")}
CLI = "servobus.protocols.dyn232.sim_cmd:register"
DECODERS: dict[str, str] = {"dyn232": "servobus.protocols.dyn232.sniff:DECODER"}
PARAMS: dict[str, str] = {"dyn232": "servobus.protocols.dyn232.commands:REACHABLE_PARAMS"}
FAMILIES: dict[str, str] = {"dyn232": "dmm-dyn2"}
