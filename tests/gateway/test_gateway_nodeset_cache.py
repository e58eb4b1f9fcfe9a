"""The NodeSet import's cache (servobus.gateway.opcua_nodesets): a start served from it has
the same address space as one that imported the XML, and an unreadable cache is an import."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from asyncua import Server, ua
from asyncua.server.internal_server import InternalServer

from servobus.gateway.opcua_cache import load_standard
from servobus.gateway.opcua_nodesets import import_nodesets

pytestmark = pytest.mark.slow  # three asyncua address spaces: seconds of CPU


class CachedStandard(InternalServer):  # type: ignore[misc]
    """asyncua's server with its standard nodes from the user's cache, as every gateway's
    start (test_gateway_start_cache: they are the built ones): 2 s of CPU less per address
    space; the NodeSets, what this file tests, are imported or cached as in a gateway."""

    async def load_standard_address_space(self, shelf_file: Path | None = None) -> None:
        await load_standard(self, super().load_standard_address_space)


async def address_space(cache: Path) -> tuple[bool, Server]:
    server = Server(iserver=CachedStandard())
    await server.init()
    await server.set_application_uri("urn:servobus:gateway:cache-test")
    return await import_nodesets(server, cache), server


def snapshot(server: Server) -> dict[ua.NodeId, list[tuple[object, ...]]]:
    return {nodeid: sorted((str(r.ReferenceTypeId), str(r.NodeId), r.IsForward)
                           for r in data.references)
            for nodeid, data in server.iserver.aspace._nodes.items()}


async def test_a_cached_import_is_the_import(tmp_path: Path,
                                              caplog: pytest.LogCaptureFixture) -> None:
    cache = tmp_path / "nodesets.pickle"
    served, imported = await address_space(cache)
    assert not served and cache.is_file()
    served, cached = await address_space(cache)
    assert served
    assert snapshot(cached) == snapshot(imported)
    axis_type = ua.NodeId(16601, await cached.get_namespace_index(
        "http://opcfoundation.org/UA/Robotics/"))
    assert (await cached.get_node(axis_type).read_browse_name()).Name == "AxisType"
    cache.write_bytes(b"not a pickle")
    with caplog.at_level(logging.WARNING):
        served, _ = await address_space(cache)
    assert not served and "unreadable" in caplog.text
