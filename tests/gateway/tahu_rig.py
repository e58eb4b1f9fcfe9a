"""An independent Sparkplug B decoder for the tests: protoc (grpcio-tools) compiles Eclipse
Tahu's ``sparkplug_b.proto`` into a temporary folder, and its generated classes read what the
gateway sent (the gateway's own classes come from servobus's schema reader instead)."""

from __future__ import annotations

import functools
import importlib.util
import tempfile
from importlib import resources
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

PROTO = "sparkplug_b.proto"


def schema_path(folder: Path) -> Path:
    path = folder / PROTO
    path.write_bytes(resources.files("servobus.gateway.sparkplug").joinpath(PROTO).read_bytes())
    return path


def protoc(folder: Path, *args: str) -> None:
    try:
        from grpc_tools import protoc as grpc_protoc
    except ImportError:
        pytest.skip("grpcio-tools is not installed (pip install grpcio-tools)")
    proto = schema_path(folder)
    code = grpc_protoc.main(["protoc", f"--proto_path={folder}", *args, str(proto)])
    assert code == 0, f"protoc failed on {proto}"


@functools.cache
def tahu() -> ModuleType:
    """The protoc-generated ``sparkplug_b_pb2`` (once per process: its file is registered in
    protobuf's default pool)."""
    folder = Path(tempfile.mkdtemp(prefix="tahu-"))
    protoc(folder, f"--python_out={folder}")
    spec = importlib.util.spec_from_file_location("tahu_sparkplug_b_pb2",
                                                  folder / "sparkplug_b_pb2.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def decode(data: bytes) -> Any:
    return tahu().Payload.FromString(data)


def metrics(message: Any) -> dict[str, Any]:
    """name -> the decoded Metric."""
    return {m.name: m for m in message.metrics}


def value(metric: Any) -> Any:
    if metric.is_null:
        return None
    which = metric.WhichOneof("value")
    return None if which is None else getattr(metric, which)


def unit(metric: Any) -> str | None:
    props = metric.properties
    for key, prop in zip(props.keys, props.values, strict=True):
        if key == "engUnit":
            return str(prop.string_value)
    return None


def dcmd(**values: float | bool) -> tuple[bytes, Any]:
    """A DCMD payload written with the Tahu classes: ``Commands/<name>`` = value, stamped
    now; (its bytes, the message to change and serialize again)."""
    import time

    module = tahu()
    message = module.Payload(timestamp=int(time.time() * 1000))
    for name, val in values.items():
        metric = message.metrics.add(name=f"Commands/{name}")
        if isinstance(val, bool):
            metric.datatype = module.Boolean
            metric.boolean_value = val
        else:
            metric.datatype = module.Double
            metric.double_value = val
    return message.SerializeToString(), message
