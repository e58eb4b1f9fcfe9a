"""REST: the Tuning tab's "Auto" (servobus.gui.autotune): confirm, start, cancel, revert.

``POST /api/axes/N/tuning/auto`` {distance, unit, page, save, confirmed}: without
``confirmed`` the checks and the question (nothing moves), with it the run starts, owned by
``page`` (its WebSocket's ``hello`` owner, which must be connected: it renews the run).
``GET`` gives the axis's run (progress, then the table) and whether its family saves
gains on request (the page's save box); ``/cancel`` aborts it (any page:
Stop always wins), ``/revert`` writes the last run's kept gains back.
"""

from __future__ import annotations

from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from servobus.errors import ArgumentRangeError
from servobus.gui.http_util import api, body, handle, integer, number, ok, state
from servobus.tune import plan
from servobus.tune.tuner import GOALS


def _page(request: Request, doc: dict[str, object]) -> int:
    page = integer(doc, "page")
    if page not in state(request).jog.pages:
        raise ArgumentRangeError(f"no page {page} is connected: an auto-tune run needs the "
                                 "page's WebSocket, which renews it")
    return page


@api
async def auto_state(request: Request) -> Response:
    h = handle(request)
    gui = state(request)
    page = int(request.query_params.get("page", "0") or 0)
    profile = h.axis.family.tuning
    return JSONResponse({"run": gui.autotune.views(page).get(str(h.id)),
                         "can_save": plan.saves_with_command(profile),
                         "save_hint": profile.save_hint if profile is not None else ""})


@api
async def auto_start(request: Request) -> Response:
    h = handle(request)
    gui = state(request)
    doc = await body(request)
    page = _page(request, doc)
    value, unit = number(doc, "distance"), str(doc.get("unit", h.units().position))
    save = bool(doc.get("save", False))
    goal = doc.get("goal", "settling")
    if goal not in GOALS:
        raise ArgumentRangeError(f"goal {goal!r}: one of {', '.join(GOALS)}; nothing was "
                                 "moved")
    if not doc.get("confirmed"):
        return ok(started=False, **await gui.autotune.ask(h, page, value, unit, save))
    run = await gui.autotune.start(h, page, value, unit, save, goal=str(goal))
    return ok(started=True, run=run.view(run.owner))


@api
async def auto_cancel(request: Request) -> Response:
    h = handle(request)
    await body(request)
    run = await state(request).autotune.cancel(h.id, "cancelled")
    if run is None:
        raise ArgumentRangeError(f"{h.label}: no auto-tune run to cancel")
    return ok(run=run.view(run.owner))


@api
async def auto_revert(request: Request) -> Response:
    h = handle(request)
    await body(request)
    return ok(restored=await state(request).autotune.revert(h))


ROUTES = [
    Route("/api/axes/{axis}/tuning/auto", auto_state),
    Route("/api/axes/{axis}/tuning/auto", auto_start, methods=["POST"]),
    Route("/api/axes/{axis}/tuning/auto/cancel", auto_cancel, methods=["POST"]),
    Route("/api/axes/{axis}/tuning/auto/revert", auto_revert, methods=["POST"]),
]
