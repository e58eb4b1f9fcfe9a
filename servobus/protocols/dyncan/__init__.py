"""DYN CAN 2.0A for DMM DYN2 / DYN4 drives, docs/dyncan.md.

URLs: ``dyncan+<python-can interface>://<channel>``, e.g. ``dyncan+pcan://PCAN_USBBUS1``,
``dyncan+socketcand://127.0.0.1:29536/can0``, ``dyncan+virtual://bus0``; ``?bitrate=``.
``sim://dyncan`` runs virtual nodes on an in-process python-can virtual bus.
"""

from servobus.protocols import ProtocolSpec

SPEC = ProtocolSpec(
    name="dyncan",
    family="dmm-dyn2",
    opener="servobus.protocols.dyncan.opener:open_axis",
    schemes=("dyncan",),
    sim="servobus.protocols.dyncan.inprocess:open_sim_axis",
    cli="servobus.protocols.dyncan.cli:register",
    decoder="servobus.protocols.dyncan.sniff:DECODER",
    params="servobus.protocols.dyncan.commands:REACHABLE_PARAMS",
    shortcuts=(("can", "dyncan+{interface}://{channel}"),),
)
