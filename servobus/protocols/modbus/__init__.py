"""Modbus RTU: the YZ-AIM TTL serial port (19200 8N1), docs/modbus.md.

``crc`` CRC-16/MODBUS; ``codec`` frames <-> frozen dataclasses for both sides; ``timing``
character and inter-frame times; ``framer`` cutting a byte stream into frames (by silence
and content for a line or sniffer, by predicted length for a host awaiting a reply);
``client``/``policy``/``axis``/``opener`` the host side; ``device``/``pacing``/``server``/
``inprocess``/``cli`` the virtual line of YZ-AIM motors; ``sniff`` decode/sniff.

URLs: ``modbus:///dev/ttyUSB0?baud=19200``, ``modbus:COM3``, ``modbus+socket://HOST:PORT``
(any pyserial URL after the ``+``); ``sim://modbus`` is the in-process virtual line.
"""

from servobus.protocols import ProtocolSpec

SPEC = ProtocolSpec.conventional("modbus", "yzaim",
                                  params="servobus.protocols.modbus.params:REACHABLE_PARAMS")
