"""REST: the axes, motion commands, STOP ALL and diagnostics."""

from __future__ import annotations

import contextlib
import time

from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from servobus import __version__
from servobus.axis.units import DRIVE_UNITS, to_counts
from servobus.errors import ArgumentRangeError
from servobus.gui.fleet import AxisHandle
from servobus.gui.http_util import api, body, handle, integer, number, ok, state
from servobus.gui.signals import SIGNALS
from servobus.gui.soft_limits import check_wave

ACTIONS = ("enable", "disable", "stop", "set_origin", "reset")
#: Actions that end a running jog, constant speed or tuning run first (whoever holds it:
#: Stop wins).
ENDS_LEASE = ("disable", "stop", "set_origin", "reset")
WAVES = ("square", "sine", "off")


@api
async def info(request: Request) -> Response:
    gui = state(request)
    return JSONResponse({
        "version": __version__, "url": gui.fleet.url, "started": time.time(),
        "axes": [h.identity() for h in gui.fleet.handles.values()],
        "signals": [{"name": s.name, "unit": s.unit, "label": s.label}
                    for s in SIGNALS.values()],
        "units": list(DRIVE_UNITS), "jog_lease_s": gui.jog.lease_s,
        "machine": gui.fleet.machine.name if gui.fleet.machine_file and gui.fleet.machine
        else None,
    })


@api
async def axes(request: Request) -> Response:
    gui = state(request)
    now = time.time()
    return JSONResponse([{"identity": h.identity(), "status": gui.monitor.view(i, now)}
                         for i, h in gui.fleet.handles.items()])


async def _refresh(request: Request, axis_id: int) -> dict[str, object]:
    """A status read right after a command (the page sees the effect at once)."""
    gui = state(request)
    with contextlib.suppress(Exception):  # the periodic monitor reports link problems
        await gui.monitor.read(gui.fleet.get(axis_id))
    return gui.monitor.view(axis_id)


@api
async def command(request: Request) -> Response:
    h = handle(request)
    action = (await body(request)).get("action")
    if action not in ACTIONS:
        raise ArgumentRangeError(f"action {action!r}: one of {', '.join(ACTIONS)}")
    m = h.machine_axis
    busy = m is not None and (m.lease is not None or m.tuning_owner is not None)
    if m is not None and (action == "stop" or (action in ENDS_LEASE and busy)):
        await h.call(m.stop())  # ends the lease or tuning run first: no target update after
    if action != "stop" or m is None:
        await h.call(getattr(h.axis, str(action))())
    return ok(status=await _refresh(request, h.id))


@api
async def move(request: Request) -> Response:
    h = handle(request)
    doc = await body(request)
    value, unit = number(doc, "value"), str(doc.get("unit", "counts"))
    relative = bool(doc.get("relative", False))
    m = h.machine_axis
    if m is not None and h.named:  # a machine axis: its own unit, its limits before the wire
        user = value if unit == m.unit else m.to_user(to_counts(value, unit, h.axis.counts_per_rev))
        await h.call(m.move_by(user) if relative else m.move_to(user))
        return ok(counts=m.to_counts(user), relative=relative, value=user, unit=m.unit,
                  status=await _refresh(request, h.id))
    counts = to_counts(value, unit, h.axis.counts_per_rev)
    if m is not None:  # a bare URL's axis, in counts: a move replaces a running lease
        await h.call(m.move_by(counts) if relative else m.move_to(counts))
    elif relative:
        await h.call(h.axis.move_by(counts))
    else:
        await h.call(h.axis.move_to(counts))
    return ok(counts=counts, relative=relative, status=await _refresh(request, h.id))


@api
async def turn(request: Request) -> Response:
    """Constant speed at ``speed`` (the axis's speed unit; ``rpm`` still taken): a lease
    owned by the page ``page`` (its ``hello`` owner; the page
    renews it over its WebSocket) or, without ``page``, by this REST client (renewed by
    posting again within ``ttl`` s, at most 1). Open-ended on a continuous axis."""
    h = handle(request)
    doc = await body(request)
    units = h.units()
    speed = number(doc, "speed") if "speed" in doc else integer(doc, "rpm") * units.per_rpm
    page = integer(doc, "page") if doc.get("page") is not None else None
    ttl = number(doc, "ttl") if doc.get("ttl") is not None else None
    result = await state(request).jog.turn(h.id, speed, page=page, ttl=ttl)
    return ok(rpm=round(speed / units.per_rpm), speed=speed, speed_unit=units.speed, **result)


@api
async def wave(request: Request) -> Response:
    """Drive-generated test motion (families with "waves"): offset +- amplitude checked
    against the soft limits first (servobus.gui.soft_limits), then frequency, then the
    wave; ``off`` sets the frequency to 0 (the drive stops the wave). Not leased: it runs
    until Off, Stop, STOP ALL or the GUI's shutdown."""
    h = handle(request)
    doc = await body(request)
    kind = doc.get("kind")
    if kind not in WAVES:
        raise ArgumentRangeError(f"wave {kind!r}: one of {', '.join(WAVES)}")
    if kind == "off":
        await h.call(h.axis.wave_frequency(0))
        return ok()
    hz, amplitude = integer(doc, "hz"), _wave_amplitude(h, doc)  # both before any send
    if hz < 1:
        raise ArgumentRangeError(f"hz={hz}: a wave runs at 1 Hz or more (\"off\" stops it)")
    await check_wave(h, amplitude)  # soft limits and leases, before anything is sent
    await h.call(h.axis.wave_frequency(hz))
    if kind == "square":
        await h.call(h.axis.square_wave(amplitude))
    else:
        await h.call(h.axis.sine_wave(amplitude))
    return ok()


def _wave_amplitude(h: AxisHandle, doc: dict[str, object]) -> int:
    """The amplitude in the drive's wave units: given in the axis's shown unit when the
    body names ``unit`` (the page does: mm, deg, counts), else in wave units as before."""
    if doc.get("unit") is None:
        return integer(doc, "amplitude")
    value, unit = number(doc, "amplitude"), str(doc.get("unit"))
    units = h.units()
    if unit != units.position:
        raise ArgumentRangeError(f"{h.label}: a wave's amplitude is in {units.position}, "
                                 f"not {unit}")
    per_unit = h.axis.family.wave_counts_per_unit
    if per_unit <= 0:
        raise ArgumentRangeError(f"{h.label}: the family gives no wave scale; nothing "
                                 "was sent")
    amplitude = round(abs(h.to_counts(value)) / per_unit)
    if amplitude < 1 and value != 0:
        raise ArgumentRangeError(f"{h.label}: a wave amplitude of {value:g} {unit} is less "
                                 f"than the drive's smallest "
                                 f"({per_unit * abs(units.per_count):g} {unit}); nothing "
                                 "was sent")
    return amplitude


@api
async def acknowledge(request: Request) -> Response:
    """A person has seen the axis's power-loss flag and interrupted motion (issue 29): the
    machine axis's ``acknowledge()`` clears both and motion is allowed again. Nothing is
    sent to the drive. A JSON POST like every command (the Guard's token and CSRF rules)."""
    h = handle(request)
    await body(request)
    m = h.machine_axis
    if m is not None:
        what = m.power_lost_reason or m.interrupted
        await m.acknowledge()
        if what is not None:
            state(request).monitor.acknowledged(h.id, what)
    return ok(status=state(request).monitor.view(h.id))


@api
async def stop_all(request: Request) -> Response:
    results = await state(request).stop_all()
    return ok(axes={str(k): v for k, v in results.items()},
              failed=[k for k, v in results.items() if v])


@api
async def diagnostics(request: Request) -> Response:
    gui = state(request)
    after = int(request.query_params.get("after", "0") or 0)
    return JSONResponse({
        "alarms": list(gui.monitor.log),
        "links": {str(i): h.link() for i, h in gui.fleet.handles.items()},
        "traffic": gui.fleet.traffic.recent(300, after),
        "traffic_counts": gui.fleet.traffic.counts,
        "samplers": [s.describe() for s in gui.samplers.values()],
        "scopes": [s.state() for s in gui.sessions],
        "jog": {"active": {str(k): v["rpm"] for k, v in gui.jog.active().items()},
                "stops": gui.jog.stops},
    })


ROUTES = [
    Route("/api/info", info),
    Route("/api/axes", axes),
    Route("/api/axes/{axis}/command", command, methods=["POST"]),
    Route("/api/axes/{axis}/move", move, methods=["POST"]),
    Route("/api/axes/{axis}/turn", turn, methods=["POST"]),
    Route("/api/axes/{axis}/wave", wave, methods=["POST"]),
    Route("/api/axes/{axis}/acknowledge", acknowledge, methods=["POST"]),
    Route("/api/stop_all", stop_all, methods=["POST"]),
    Route("/api/diagnostics", diagnostics),
]
