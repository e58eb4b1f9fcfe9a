"""DYN CAN 2.0A for DMM DYN2 / DYN4 drives, docs/dyncan.md.

URLs: ``dyncan+<python-can interface>://<channel>``, e.g. ``dyncan+pcan://PCAN_USBBUS1``,
``dyncan+socketcand://127.0.0.1:29536/can0``, ``dyncan+virtual://bus0``; ``?bitrate=``.
``sim://dyncan`` runs virtual nodes on an in-process python-can virtual bus.
"""

from servobus.protocols import ProtocolSpec

SPEC = ProtocolSpec.conventional("dyncan", "dmm-dyn2",
                                  shortcuts=(("can", "dyncan+{interface}://{channel}"),),
                                  link="can")
