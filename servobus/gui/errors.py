"""Typed errors -> HTTP answers: ``{"error": "what happened"}`` with a fitting status."""

from __future__ import annotations

from starlette.responses import JSONResponse

from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveAlarm,
    DriveTimeout,
    NotSupported,
    OwnerError,
    PowerLostError,
    ServobusError,
)
from servobus.families.params_file import ParamsFileError

#: Most specific first.
STATUS: tuple[tuple[type[BaseException], int], ...] = (
    (NotSupported, 501),
    (OwnerError, 409),  # another page or client holds the axis
    (PowerLostError, 409),  # acknowledge the possible power loss first
    (ParamsFileError, 400),
    (ArgumentRangeError, 400),
    (DriveAlarm, 409),
    (DriveTimeout, 504),
    (ConnectionLost, 503),
    (ServobusError, 502),
    (ValueError, 400),
    (KeyError, 404),
)


def error_response(exc: BaseException) -> JSONResponse:
    for kind, status in STATUS:
        if isinstance(exc, kind):
            return JSONResponse({"error": str(exc), "kind": type(exc).__name__}, status)
    raise exc
