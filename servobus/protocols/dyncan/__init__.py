"""DYN CAN 2.0A for DMM DYN2 / DYN4 drives, docs/dyncan.md.

URLs: ``dyncan+<python-can interface>://<channel>``, e.g. ``dyncan+pcan://PCAN_USBBUS1``,
``dyncan+socketcand://127.0.0.1:29536/can0``, ``dyncan+virtual://bus0``; ``?bitrate=``.
``sim://dyncan`` runs virtual nodes on an in-process python-can virtual bus.
"""

SCHEMES: dict[str, str] = {"dyncan": "servobus.protocols.dyncan.opener:open_axis"}
SIM: dict[str, str] = {"dyncan": "servobus.protocols.dyncan.inprocess:open_sim_axis"}
CLI = "servobus.protocols.dyncan.sim_cmd:register"
DECODERS: dict[str, str] = {"dyncan": "servobus.protocols.dyncan.sniff:DECODER"}
SHORTCUTS: dict[str, str] = {"can": "dyncan+{interface}://{channel}"}
PARAMS: dict[str, str] = {"dyncan": "servobus.protocols.dyncan.commands:REACHABLE_PARAMS"}
FAMILIES: dict[str, str] = {"dyncan": "dmm-dyn2"}
