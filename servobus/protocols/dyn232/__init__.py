"""DYN232M: DMM's 7-bit serial packets over RS232/RS485 (DYN2 / DC2 / DYN4), docs/dyn232.md.

URLs: ``dyn232:///dev/ttyUSB0``, ``dyn232:COM3``, ``dyn232+socket://host:port`` (any pyserial
URL after the ``+``); a bare port or pyserial URL (``/dev/ttyUSB0``, ``socket://``, ``loop://``)
is DYN232M too. ``sim://dyn232`` (aliases ``dyn2``, ``dc2``, ``dyn4``) is the in-process line.
"""

from servobus.protocols import ProtocolSpec

#: pyserial's URL handlers (serial.serial_for_url) are bare serial ports: DYN232M.
PYSERIAL_SCHEMES = ("socket", "tcp", "loop", "rfc2217", "spy", "alt", "hwgrep", "cp2110")

#: A serial-to-Ethernet bridge: one TCP connection, a drive that speaks only when asked
#: (issue 22: the sync facade runs these calls on the caller's thread).
SPEC = ProtocolSpec.conventional("dyn232", "dmm-dyn2", sim_aliases=("dyn2", "dc2", "dyn4"),
                                  serial_schemes=("", *PYSERIAL_SCHEMES),
                                  inline_schemes=("socket", "tcp"))
