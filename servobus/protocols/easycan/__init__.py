"""EasyCan: the CAN 2.0A protocol of YZ-AIM integrated servo motors (manual section 5).

``functions`` holds the one table (function codes, frame lengths, error codes),
``messages`` the frozen dataclasses, ``codec`` (arbitration id, data) <-> messages in both
directions, ``describe`` one line per frame for decode/sniff, ``commands`` the host's pure
commands, ``client``/``axis``/``opener`` the host side, ``device``/``server``/
``inprocess``/``cli`` the virtual motors' side, ``sync`` synchronised multi-axis motion.
Registers, ranges and units are the YZ-AIM family's (servobus.families.yzaim.registers).
This module only declares its ProtocolSpec (nothing heavy is imported:
docs/architecture.md).

URLs: ``easycan+<python-can interface>://<channel>``, e.g. ``easycan+pcan://PCAN_USBBUS1``,
``easycan+socketcand://127.0.0.1:29536/can0``, ``easycan+virtual://bus0``; ``sim://easycan``
runs virtual YZ-AIM motors on an in-process python-can virtual bus (docs/easycan.md).
"""

from servobus.protocols import ProtocolSpec

SPEC = ProtocolSpec.conventional("easycan", "yzaim", link="can")
