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
what it added as a pickle in the user's cache folder (``$XDG_CACHE_HOME/servobus``, else
``~/.cache/servobus``): the new nodes and the references it added to the standard ones,
keyed by a hash of the NodeSet files, asyncua's and Python's versions. A later start with
the same key and the same namespace indexes puts them into the address space directly.
The file is written atomically (a rename), so gateways that start together do not read a
half-written one; one that cannot be read or written is a one-line notice and a plain
import. asyncua's own shelf cache of the standard address space was measured slower than
its generated code here and is not used. :data:`import_seconds` holds the last import's
time and the log names it (docs/gateway.md gives the figures). The cache folder is the
user's own, as trusted as the installed code (pickle runs what it loads).
"""

from __future__ import annotations

import hashlib
import logging
import os
import pickle
import sys
import tempfile
import time
from importlib import metadata, resources
from pathlib import Path
from typing import Any

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


def cache_path() -> Path:
    """Where the import is kept: named by what it depends on."""
    digest = hashlib.sha256()
    digest.update(f"{metadata.version('asyncua')} {sys.version} {CACHE_FORMAT}".encode())
    folder = resources.files("servobus.gateway") / "nodesets"
    for name in FILES:
        digest.update((folder / name).read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "servobus"
    return base / f"opcua-nodesets-{digest.hexdigest()[:16]}.pickle"


CACHE_FORMAT = 1
URIS = (DI_URI, IA_URI, ROBOTICS_URI)


async def import_nodesets(server: Server, cache: Path | None = None) -> bool:
    """Import the three NodeSets into ``server`` (after ``init`` and the ApplicationUri, so
    namespace 1 stays the gateway's own), from ``cache`` (default :func:`cache_path`) when
    it holds them; True when the cache served."""
    global import_seconds
    start = time.perf_counter()
    path = cache if cache is not None else cache_path()
    served = await _from_cache(server, path)
    if not served:
        await _import(server, path)
    import_seconds = time.perf_counter() - start
    log.info("OPC UA NodeSets DI, IA and Robotics %s in %.2f s",
             "from the cache" if served else "imported", import_seconds)
    return served


async def _from_cache(server: Server, path: Path) -> bool:
    try:
        with path.open("rb") as f:
            kept: dict[str, Any] = pickle.load(f)
    except FileNotFoundError:
        return False
    except Exception as exc:  # any unreadable cache: import instead
        log.warning("OPC UA NodeSet cache %s unreadable (%s): importing", path, exc)
        return False
    indexes = [await server.register_namespace(uri) for uri in URIS]
    if indexes != kept["indexes"]:
        return False  # another namespace layout: the ids in the cache do not fit
    nodes = server.iserver.aspace._nodes
    nodes.update(kept["nodes"])
    for nodeid, refs in kept["references"].items():
        nodes[nodeid].references.extend(refs)
    return True


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
    temporary: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("wb", dir=path.parent, delete=False) as f:
            temporary = f.name
            pickle.dump(kept, f, pickle.HIGHEST_PROTOCOL)
        os.replace(temporary, path)
    except Exception as exc:  # no cache: the next start imports again
        log.warning("OPC UA NodeSet cache %s not written (%s)", path, exc)
        if temporary is not None:
            Path(temporary).unlink(missing_ok=True)
