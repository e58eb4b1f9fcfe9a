"""The OPC UA companion specifications the gateway's types come from, imported at start.

Decision (issue 36, docs/gateway.md "Information model"): the official NodeSets of DI
(OPC 10000-100, 1.04.0), IA (OPC 10000-200, 1.01.2, which Robotics needs) and Robotics
(OPC 40010-1, 1.01.2) ship unmodified as package data (``nodesets/``, with their MIT
licence) and asyncua imports them before the machine's nodes are built, so every NodeId
of a type, of ``DeviceSet`` (DI ``i=5001``) and of an enumeration is the official one. DI
1.05.0 does not import in asyncua 2.1 (BadParentNodeIdInvalid); 1.04.0 does, and nothing
of 1.05 is used. A faithful subset was the fallback; not needed.

What it costs: about 800 nodes; asyncua spends most of it on adding references, not on
parsing. asyncua's own cache of the standard address space (a shelf) was measured slower
than its generated code on this machine, so nothing is cached; :data:`import_seconds`
holds the last import's time and ``servobus serve`` logs it (docs/gateway.md gives the
figures).
"""

from __future__ import annotations

import logging
import time
from importlib import resources

from asyncua import Server

log = logging.getLogger(__name__)

DI_URI = "http://opcfoundation.org/UA/DI/"
IA_URI = "http://opcfoundation.org/UA/IA/"
ROBOTICS_URI = "http://opcfoundation.org/UA/Robotics/"
#: In dependency order: IA and Robotics need DI.
FILES = ("Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.IA.NodeSet2.xml", "Opc.Ua.Robotics.NodeSet2.xml")


class NodeSetIds:
    """Official NodeIds (numeric, in their model's namespace) the model uses."""

    DEVICE_SET = 5001  # DI
    MOTION_DEVICE_SYSTEM_TYPE = 1002  # Robotics
    MOTION_DEVICE_TYPE = 1004
    AXIS_TYPE = 16601
    POWER_TRAIN_TYPE = 16794
    MOTOR_TYPE = 1019
    CONTROLLER_TYPE = 1003
    SAFETY_STATE_TYPE = 1013
    CONTROLS = 4002  # reference types
    MOVES = 18178
    REQUIRES = 18179
    IS_DRIVEN_BY = 18180
    HAS_SAFETY_STATES = 18182


#: Seconds the last :func:`import_nodesets` took (None before any).
import_seconds: float | None = None


async def import_nodesets(server: Server) -> None:
    """Import the three NodeSets into ``server`` (after ``init`` and the ApplicationUri, so
    namespace 1 stays the gateway's own)."""
    global import_seconds
    start = time.perf_counter()
    folder = resources.files("servobus.gateway") / "nodesets"
    quiet = logging.getLogger("asyncua.common.xmlimporter")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # one warning per optional type asyncua cannot build
    try:
        for name in FILES:
            with resources.as_file(folder / name) as path:
                await server.import_xml(str(path))
    finally:
        quiet.setLevel(level)
    import_seconds = time.perf_counter() - start
    log.info("OPC UA NodeSets DI, IA and Robotics imported in %.2f s", import_seconds)
