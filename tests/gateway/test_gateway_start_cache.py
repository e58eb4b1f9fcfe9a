"""The caches of the gateway's OPC UA start (servobus.gateway.opcua_cache): a gateway whose
standard address space and NodeSets come from them is the gateway that built them, typed
for a client that browses by TypeDefinition; a damaged, foreign or stale file is built
again; the files are per user and named by what they depend on."""

from __future__ import annotations

import json
import logging
import pickle
import subprocess
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest
from asyncua import Client, ua
from asyncua.server.address_space import NodeData
from asyncua.server.internal_server import InternalServer
from fake_machine import FakeMachine
from gateway_rig import find_by_type

from servobus.gateway import opcua_cache, opcua_nodesets
from servobus.gateway.commands import Commander
from servobus.gateway.opcua_nodesets import DI_URI, ROBOTICS_URI, NodeSetIds
from servobus.gateway.opcua_server import OpcUaGateway, OpcUaOptions

Snapshot = dict[ua.NodeId, tuple[list[tuple[object, ...]], dict[int, object]]]


def snapshot(nodes: dict[ua.NodeId, NodeData]) -> Snapshot:
    """Every node's references and attribute values."""
    return {nodeid: (sorted((str(r.ReferenceTypeId), str(r.NodeId), r.IsForward)
                            for r in data.references),
                     {int(key): value.value for key, value in data.attributes.items()})
            for nodeid, data in nodes.items()}


def tiny_build(iserver: InternalServer) -> Callable[[], Awaitable[None]]:
    """A stand-in for asyncua's filling: the landmarks only (a real one takes seconds)."""
    async def build() -> None:
        for ident in opcua_cache.STANDARD_LANDMARKS:
            iserver.aspace._nodes[ua.NodeId(ident)] = NodeData(ua.NodeId(ident))
    return build


async def standard(path: Path, real: bool = False) -> tuple[bool, InternalServer]:
    iserver = InternalServer()
    build = iserver.load_standard_address_space if real else tiny_build(iserver)
    served = await opcua_cache.load_standard(iserver, build, path)
    return served, iserver


@pytest.mark.slow  # asyncua's standard address space built once: seconds of CPU
@pytest.mark.timeout(180)
async def test_the_standard_address_space_from_the_cache_is_the_built_one(
        tmp_path: Path) -> None:
    path = tmp_path / "standard.pickle"
    served, built = await standard(path, real=True)
    assert not served and path.is_file()
    served, loaded = await standard(path, real=True)
    assert served
    assert snapshot(loaded.aspace._nodes) == snapshot(built.aspace._nodes)


@pytest.mark.slow  # two gateways in this process: seconds of CPU
@pytest.mark.timeout(180)
async def test_a_gateway_from_the_caches_is_typed_for_a_client() -> None:
    """The user's cache, as every gateway test's: the first start builds it when it is
    missing, the second is served from it either way."""
    for start in ("either", "loads"):
        machine = FakeMachine()
        gateway = OpcUaGateway(machine, Commander(machine),  # type: ignore[arg-type]
                               OpcUaOptions("opc.tcp://127.0.0.1:0"))
        await gateway.start()
        try:
            if start == "either":
                continue
            assert gateway.server.iserver.standard_from_cache
            assert opcua_nodesets.served_from_cache
            async with Client(gateway.endpoint) as client:  # a client that knows types only
                di = await client.get_namespace_index(DI_URI)
                rob = await client.get_namespace_index(ROBOTICS_URI)
                device_set = client.get_node(ua.NodeId(NodeSetIds.DEVICE_SET, di))
                axes = await find_by_type(device_set, ua.NodeId(NodeSetIds.AXIS_TYPE, rob))
                assert sorted([(await a.read_browse_name()).Name for a in axes]) == \
                    sorted(machine.axes)
        finally:
            await gateway.stop()


async def test_a_damaged_or_foreign_cache_is_built_again(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "standard.pickle"
    served, built = await standard(path)
    assert not served and path.is_file()
    served, loaded = await standard(path)
    assert served and snapshot(loaded.aspace._nodes) == snapshot(built.aspace._nodes)
    whole = path.read_bytes()
    for content in (whole[:len(whole) // 2], b"not a pickle"):  # a crash mid-write, noise
        path.write_bytes(content)
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            served, again = await standard(path)
        assert not served and "unreadable" in caplog.text
        assert snapshot(again.aspace._nodes) == snapshot(built.aspace._nodes)
        assert opcua_cache.is_standard(opcua_cache.read(path))  # written anew, whole
    opcua_cache.write(path, {"what": "something else"})  # a cache of another kind
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        served, _ = await standard(path)
    assert not served and "holds no standard address space" in caplog.text
    assert opcua_cache.is_standard(opcua_cache.read(path))
    copy = tmp_path / "copied.pickle"  # a file written under another name (key)
    copy.write_bytes(path.read_bytes())
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        assert opcua_cache.read(copy) is None
    assert "written as another file" in caplog.text


def test_the_file_is_the_users_and_named_by_what_it_depends_on(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    first = opcua_cache.standard_cache_file()
    assert first.parent == tmp_path / "servobus" and first.name.startswith("opcua-standard-")
    assert opcua_cache.standard_cache_file() == first  # the same at every start
    assert opcua_cache.cache_file("nodesets", b"DI 1.04") != \
        opcua_cache.cache_file("nodesets", b"DI 1.05")
    monkeypatch.setattr(opcua_cache, "__version__", "99.0")  # another servobus
    assert opcua_cache.standard_cache_file() != first
    monkeypatch.undo()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(opcua_cache.metadata, "version", lambda name: "0.0.1")  # asyncua
    assert opcua_cache.standard_cache_file() != first
    monkeypatch.undo()
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert opcua_cache.folder() == tmp_path / "home" / ".cache" / "servobus"


def test_a_file_is_written_whole_or_not_at_all(tmp_path: Path,
                                               caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "cache" / "kept.pickle"
    opcua_cache.write(path, [1, 2, 3])
    assert opcua_cache.read(path) == [1, 2, 3]
    assert [p.name for p in path.parent.iterdir()] == ["kept.pickle"]  # no temporary left
    with path.open("rb") as f:
        assert pickle.load(f) == {"file": "kept.pickle", "value": [1, 2, 3]}
    blocked = tmp_path / "a file" / "kept.pickle"
    blocked.parent.write_text("not a folder")
    with caplog.at_level(logging.WARNING):
        opcua_cache.write(blocked, [1])
    assert "not written" in caplog.text
    assert opcua_cache.read(blocked) is None


PLAIN_SERVE = """
import json, sys
from servobus.cli.main import cli
serve = cli.get_command(None, "serve")
import servobus.gateway.serve
loaded = sorted(m for m in ("aiomqtt", "paho", "google.protobuf", "servobus.cli.tune_cmd",
                            "servobus.cli.protocol_cmds", "servobus.gateway.mqtt")
                if m in sys.modules)
print(json.dumps({"serve": serve is not None, "loaded": loaded,
                  "all": "tune" in cli.commands and cli.get_command(None, "serve") is serve}))
"""


@pytest.mark.slow  # a Python process that imports asyncua
def test_a_plain_serve_imports_neither_mqtt_nor_the_other_commands() -> None:
    """Start-up time (docs/gateway.md): ``servobus serve`` loads its own command module,
    and MQTT's libraries only with --mqtt; listing the commands loads them all."""
    proc = subprocess.run([sys.executable, "-c", PLAIN_SERVE], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == {
        "serve": True, "loaded": [], "all": True}
