"""Small helpers shared by the REST handlers: the app's state, JSON bodies, typed errors."""

from __future__ import annotations

import functools
import math
from collections.abc import Awaitable, Callable

from starlette.requests import Request
from starlette.responses import JSONResponse, Response

from servobus import bounded_json
from servobus.errors import ArgumentRangeError, JsonRefused
from servobus.gui import limits
from servobus.gui.errors import error_response
from servobus.gui.fleet import AxisHandle
from servobus.gui.state import GuiState

Handler = Callable[[Request], Awaitable[Response]]


def state(request: Request) -> GuiState:
    gui: GuiState = request.app.state.gui
    return gui


def handle(request: Request) -> AxisHandle:
    try:
        axis_id = int(request.path_params["axis"])
    except ValueError:
        raise ArgumentRangeError(f"axis {request.path_params['axis']!r} is not a number") \
            from None
    return state(request).fleet.get(axis_id)


async def body(request: Request) -> dict[str, object]:
    """The JSON object of the body (bounded: servobus.gui.limits, servobus.bounded_json)."""
    try:
        doc = bounded_json.loads(await request.body(), max_bytes=limits.MAX_BODY_BYTES)
    except JsonRefused as exc:
        raise ArgumentRangeError(f"the request body is refused: {exc}") from None
    if not isinstance(doc, dict):
        raise ArgumentRangeError("the request body must be a JSON object")
    return doc


def number(doc: dict[str, object], key: str, default: float | None = None) -> float:
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ArgumentRangeError(f"{key} must be a finite number, got {value!r}")
    return float(value)


def integer(doc: dict[str, object], key: str, default: int | None = None) -> int:
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ArgumentRangeError(f"{key} must be an integer, got {value!r}")
    return value


def api(fn: Handler) -> Handler:
    """Typed errors become ``{"error": ...}`` answers (servobus.gui.errors)."""

    @functools.wraps(fn)
    async def wrapped(request: Request) -> Response:
        try:
            return await fn(request)
        except Exception as exc:  # mapped to a status, or re-raised (a bug: 500)
            return error_response(exc)

    return wrapped


def ok(**fields: object) -> JSONResponse:
    return JSONResponse({"ok": True, **fields})
