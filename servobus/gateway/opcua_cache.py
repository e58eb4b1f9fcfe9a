"""What the gateway's OPC UA start builds the same way every time, kept in the user's cache.

Decision (issue 36, docs/gateway.md "Start-up time"): asyncua builds its standard address
space (about 6,000 nodes) from generated code at every start, and the DI, IA and Robotics
NodeSets from XML (servobus.gateway.opcua_nodesets); together most of the time to
``ready``. Both come out the same at every start of the same installation, so the first
start keeps them as pickles and later ones load them:

* where: ``$XDG_CACHE_HOME/servobus``, else ``~/.cache/servobus``: the user's own folder,
  as trusted as the installed code (pickle runs what it loads);
* the file's name is a hash of everything the content depends on: the kind, this module's
  :data:`CACHE_FORMAT`, servobus's, asyncua's and Python's versions, and what the kind adds
  (the NodeSet files' bytes; the names, sizes and times of asyncua's generated standard
  address space files), so another version never reads it; the content names its file
  again, so a copied or renamed file is not taken for another;
* written to a temporary file and renamed, so gateways starting together never read half
  a file; one that cannot be read or does not hold what it should is one warning line and
  is built again (and written again); one that cannot be written is a warning line and the
  next start builds again. Old versions' files are left alone (another installation may
  use them).

The collector is off while a file is unpickled (:func:`servobus.gateway.heap.collector_off`),
in any process: the hundreds of thousands of objects it makes at once set off collection
after collection, each walking all of them again (0.5 s of CPU instead of 3 s for the
standard address space on the benchmark machine).
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import os
import pickle
import sys
import tempfile
from collections.abc import Awaitable, Callable
from importlib import metadata, util
from pathlib import Path
from typing import Any

from asyncua import ua
from asyncua.server.address_space import NodeData
from asyncua.server.internal_server import InternalServer

from servobus import __version__
from servobus.gateway.heap import collector_off

log = logging.getLogger(__name__)

#: Changed whenever what a cache file holds changes shape.
CACHE_FORMAT = 2
#: Nodes the standard address space has (a cache without them is not one).
STANDARD_LANDMARKS = (ua.ObjectIds.RootFolder, ua.ObjectIds.Server,
                      ua.ObjectIds.AlarmConditionType, ua.ObjectIds.HasComponent)


def folder() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "servobus"


def cache_file(kind: str, *inputs: bytes) -> Path:
    """The file for ``kind`` built from ``inputs`` by this installation."""
    digest = hashlib.sha256(f"{kind} {CACHE_FORMAT} servobus {__version__} asyncua "
                            f"{metadata.version('asyncua')} python {sys.version}".encode())
    for data in inputs:
        digest.update(len(data).to_bytes(8, "big"))
        digest.update(data)
    return folder() / f"opcua-{kind}-{digest.hexdigest()[:16]}.pickle"


def read(path: Path) -> Any:
    """What :func:`write` kept in ``path``; None when there is no such file, or (one
    warning line) when it cannot be read or was not written as ``path``."""
    try:
        with path.open("rb") as f, collector_off():
            kept = pickle.load(f)
    except FileNotFoundError:
        return None
    except Exception as exc:  # any unreadable cache: built again
        log.warning("OPC UA cache %s unreadable (%s): building it again", path,
                    f"{type(exc).__name__}: {exc}")
        return None
    if not isinstance(kept, dict) or kept.get("file") != path.name:
        log.warning("OPC UA cache %s unreadable (written as another file): building it "
                    "again", path)
        return None
    return kept.get("value")


def write(path: Path, value: Any) -> None:
    """Keep ``value`` in ``path``, atomically (a rename); a warning line when it cannot."""
    temporary: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("wb", dir=path.parent, prefix=".tmp-",
                                         delete=False) as f:
            temporary = f.name
            pickle.dump({"file": path.name, "value": value}, f, pickle.HIGHEST_PROTOCOL)
        os.replace(temporary, path)
    except Exception as exc:  # no cache: the next start builds again
        log.warning("OPC UA cache %s not written (%s)", path, exc)
        if temporary is not None:
            Path(temporary).unlink(missing_ok=True)


def standard_cache_file() -> Path:
    """The standard address space's file: keyed by asyncua's generated code too (an
    edited or reinstalled asyncua of the same version builds it again)."""
    spec = util.find_spec("asyncua.server.standard_address_space")
    places = spec.submodule_search_locations if spec is not None else None
    stats = []
    for place in places or []:
        for source in sorted(Path(place).glob("*.py")):
            st = source.stat()
            stats.append(f"{source.name} {st.st_size} {st.st_mtime_ns}")
    return cache_file("standard", "\n".join(stats).encode())


def is_standard(nodes: object) -> bool:
    """``nodes`` looks like asyncua's standard address space: namespace 0 only, NodeData
    only, with the landmarks."""
    if not isinstance(nodes, dict) or not all(
            isinstance(key, ua.NodeId) and key.NamespaceIndex == 0
            and isinstance(data, NodeData) for key, data in nodes.items()):
        return False
    return all(ua.NodeId(ident) in nodes for ident in STANDARD_LANDMARKS)


async def load_standard(iserver: InternalServer, build: Callable[[], Awaitable[None]],
                        path: Path | None = None) -> bool:
    """Fill ``iserver``'s empty address space with the standard nodes from the cache at
    ``path`` (default :func:`standard_cache_file`), else with ``build`` (asyncua's own
    filling) and keep the result; True when the cache served."""
    path = path if path is not None else standard_cache_file()
    nodes = await asyncio.to_thread(read, path)
    if nodes is not None and not is_standard(nodes):
        log.warning("OPC UA cache %s holds no standard address space: building it again",
                    path)
        nodes = None
    aspace = iserver.aspace._nodes
    if nodes is not None:
        aspace.update(nodes)
        return True
    await build()
    await asyncio.to_thread(write, path, dict(aspace))
    return False
