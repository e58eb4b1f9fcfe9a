"""The OPC UA companion specifications the gateway's types come from, imported at start.

Decision (issue 36, docs/gateway.md "Information model"): the official NodeSets of DI
(OPC 10000-100, 1.04.0), IA (OPC 10000-200, 1.01.2, which Robotics needs) and Robotics
(OPC 40010-1, 1.01.2) ship unmodified as package data (``nodesets/``, with their MIT
licence) and asyncua imports them before the machine's nodes are built, so every NodeId
of a type, of ``DeviceSet`` (DI ``i=5001``) and of an enumeration is the official one. DI
1.05.0 does not import in asyncua 2.1 (BadParentNodeIdInvalid); 1.04.0 does, and nothing
of 1.05 is used. A faithful subset was the fallback; not needed.

What it costs, and the cache (decision): importing takes asyncua seconds on a slow PC (about
800 nodes; most of it adding references, not parsing). The first import therefore keeps
what it added in the user's cache (servobus.gateway.opcua_cache: keyed, atomic, rebuilt
when unreadable): the new nodes and the references it added to the standard ones, keyed
by the NodeSet files too. A later start with the same namespace indexes puts them into
the address space directly. :data:`import_seconds` holds the last import's time and the
log names it (docs/gateway.md "Start-up time" gives the figures).
"""

from __future__ import annotations

import asyncio
import logging
import time
from importlib import resources
from pathlib import Path

from asyncua import Server, ua
from asyncua.server.address_space import NodeData

from servobus.gateway.opcua_cache import cache_file, read, write

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
#: Whether the last :func:`import_nodesets` was served from the cache (None before any).
served_from_cache: bool | None = None


def cache_path() -> Path:
    """Where the import is kept: named by what it depends on."""
    folder = resources.files("servobus.gateway") / "nodesets"
    return cache_file("nodesets", *((folder / name).read_bytes() for name in FILES))


URIS = (DI_URI, IA_URI, ROBOTICS_URI)


async def import_nodesets(server: Server, cache: Path | None = None) -> bool:
    """Import the three NodeSets into ``server`` (after ``init`` and the ApplicationUri, so
    namespace 1 stays the gateway's own), from ``cache`` (default :func:`cache_path`) when
    it holds them; True when the cache served."""
    global import_seconds, served_from_cache
    start = time.perf_counter()
    path = cache if cache is not None else cache_path()
    served = await _from_cache(server, path)
    if not served:
        await _import(server, path)
    import_seconds = time.perf_counter() - start
    served_from_cache = served
    log.info("OPC UA NodeSets DI, IA and Robotics %s in %.2f s",
             "from the cache" if served else "imported", import_seconds)
    return served


async def _from_cache(server: Server, path: Path) -> bool:
    kept = await asyncio.to_thread(read, path)
    if kept is None:
        return False
    nodes = server.iserver.aspace._nodes
    if not _fits(kept, nodes):
        log.warning("OPC UA cache %s holds no NodeSet import for this address space: "
                    "importing again", path)
        return False
    indexes = [await server.register_namespace(uri) for uri in URIS]
    if indexes != kept["indexes"]:
        return False  # another namespace layout: the ids in the cache do not fit
    nodes.update(kept["nodes"])
    for nodeid, refs in kept["references"].items():
        nodes[nodeid].references.extend(refs)
    return True


def _fits(kept: object, nodes: dict[ua.NodeId, NodeData]) -> bool:
    """``kept`` is an import's record that applies to ``nodes``: checked whole before any
    of it goes in, so a damaged cache never leaves half an import behind."""
    if not isinstance(kept, dict) or not isinstance(kept.get("indexes"), list):
        return False
    added, references = kept.get("nodes"), kept.get("references")
    if not isinstance(added, dict) or not isinstance(references, dict):
        return False
    return (all(isinstance(key, ua.NodeId) and isinstance(data, NodeData)
                and key not in nodes for key, data in added.items())
            and all(key in nodes and isinstance(refs, list)
                    and all(isinstance(r, ua.ReferenceDescription) for r in refs)
                    for key, refs in references.items()))


async def _import(server: Server, path: Path) -> None:
    nodes = server.iserver.aspace._nodes
    before = {nodeid: len(data.references) for nodeid, data in nodes.items()}
    folder = resources.files("servobus.gateway") / "nodesets"
    quiet = logging.getLogger("asyncua.common.xmlimporter")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # one warning per optional type asyncua cannot build
    try:
        for name in FILES:
            with resources.as_file(folder / name) as xml:
                await server.import_xml(str(xml))
    finally:
        quiet.setLevel(level)
    kept = {
        "indexes": [await server.get_namespace_index(uri) for uri in URIS],
        "nodes": {nodeid: data for nodeid, data in nodes.items() if nodeid not in before},
        "references": {nodeid: nodes[nodeid].references[count:]
                       for nodeid, count in before.items()
                       if len(nodes[nodeid].references) > count},
    }
    await asyncio.to_thread(write, path, kept)
