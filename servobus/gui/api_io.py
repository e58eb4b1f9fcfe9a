"""REST for the I/O panel: a virtual drive's JP3 inputs and outputs, and the drive config.

``GET /api/axes/{axis}/io`` answers the input ranges, the outputs and the internal state
(501 on a drive without virtual I/O: ``AsyncAxis.virtual_io()`` raises NotSupported);
``POST`` the same path sets one or more inputs: ``{"analog_v": 2.5}``, ``{"ena": false}``,
``{"pulses": {"count": 16384, "rate": 100000, "format": "pulse_dir"}}`` (format and rate
optional). The page watches the outputs and state live over the WebSocket (``io_watch``).

``GET``/``POST /api/axes/{axis}/config`` read and set the command source and servo mode
(``{"command_mode": "analog", "servo_mode": "speed"}``) on families with a config byte
(feature "config"; DYN2 manual 7.3): analog and pulse modes need it. The names are the
family's own (the axis's config enums), so the GUI holds no table of them. Decision: the
drive stores its config in EEPROM (7.3), so each change is one EEPROM write.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from servobus.axis.capabilities import Capability
from servobus.errors import ArgumentRangeError
from servobus.gui.fleet import AxisHandle
from servobus.gui.http_util import api, body, handle, integer, number, ok

CONFIG_FIELDS = ("command_mode", "servo_mode")


async def snapshot(h: AxisHandle) -> dict[str, Any]:
    """What the panel shows of one axis's virtual drive: outputs and internal state."""
    io = h.axis.virtual_io()
    return {"axis": h.id, "outputs": await io.outputs(), "state": await io.state()}


@api
async def io_read(request: Request) -> Response:
    h = handle(request)
    doc = await snapshot(h)
    return JSONResponse({**doc, "limits": h.axis.virtual_io().limits()})


@api
async def io_write(request: Request) -> Response:
    h = handle(request)
    io = h.axis.virtual_io()
    doc = await body(request)
    unknown = sorted(set(doc) - {"analog_v", "ena", "pulses"})
    if unknown or not doc:
        raise ArgumentRangeError("give analog_v, ena and/or pulses"
                                 + (f"; unknown: {', '.join(unknown)}" if unknown else ""))
    replies: dict[str, object] = {}
    if "ena" in doc:
        if not isinstance(doc["ena"], bool):
            raise ArgumentRangeError(f"ena must be true or false, got {doc['ena']!r}")
        replies["ena"] = await io.set_enable(doc["ena"])
    if "analog_v" in doc:
        replies["analog_v"] = await io.set_analog(number(doc, "analog_v"))
    if "pulses" in doc:
        train = doc["pulses"]
        if not isinstance(train, dict):
            raise ArgumentRangeError("pulses must be an object {count, rate, format}")
        fmt = train.get("format")
        if fmt is not None and not isinstance(fmt, str):
            raise ArgumentRangeError(f"pulses.format must be a name, got {fmt!r}")
        rate = number(train, "rate") if train.get("rate") is not None else None
        replies["pulses"] = await io.pulses(fmt, integer(train, "count"), rate)
    return ok(replies=replies, **await snapshot(h))


def _configurable(h: AxisHandle) -> Any:
    """The axis, when it has a config byte (Capability.CONFIG); its ``config`` and
    ``set_config`` are the family's (typed there), so the GUI holds the axis as ``Any``."""
    axis = h.axis
    axis.require(Capability.CONFIG)
    configurable: Any = axis
    return configurable


def _as_dict(cfg: Any) -> dict[str, object]:
    fields: dict[str, object] = cfg.as_dict()
    choices = {name: [m.name.lower() for m in type(getattr(cfg, name))]
               for name in CONFIG_FIELDS}
    return {**fields, "choices": choices}


@api
async def config_read(request: Request) -> Response:
    h = handle(request)
    axis = _configurable(h)
    return JSONResponse(_as_dict(await h.call(axis.config())))


@api
async def config_write(request: Request) -> Response:
    h = handle(request)
    axis = _configurable(h)
    doc = await body(request)
    unknown = sorted(set(doc) - set(CONFIG_FIELDS))
    if unknown or not doc:
        raise ArgumentRangeError(f"give {' and/or '.join(CONFIG_FIELDS)}"
                                 + (f"; unknown: {', '.join(unknown)}" if unknown else ""))
    cfg = await h.call(axis.config())
    changes: dict[str, object] = {}
    for name in CONFIG_FIELDS:
        if name not in doc:
            continue
        enum = type(getattr(cfg, name))
        wanted = doc[name]
        members = {m.name.lower(): m for m in enum}
        if not isinstance(wanted, str) or wanted not in members:
            raise ArgumentRangeError(f"{name} {wanted!r}: one of {', '.join(members)}")
        changes[name] = members[wanted]
    new = dataclasses.replace(cfg, **changes)
    if new != cfg:
        await h.call(axis.set_config(new))
    return ok(config=_as_dict(await h.call(axis.config())), changed=new != cfg)


ROUTES = [
    Route("/api/axes/{axis}/io", io_read),
    Route("/api/axes/{axis}/io", io_write, methods=["POST"]),
    Route("/api/axes/{axis}/config", config_read),
    Route("/api/axes/{axis}/config", config_write, methods=["POST"]),
]
