"""Argument checks shared by every layer: options and per-call knobs, before anything is sent.

Below the link layer (it imports nothing of servobus but the errors). Codes, ranges and
units of the drives live in the codecs and the family tables; this module only checks the
host-side numbers (deadlines, retry counts, intervals) and the plain Python types the
``make_*`` builders take. Every failure is an ArgumentRangeError naming the
argument and the value, and nothing has been sent when it is raised.
"""

from __future__ import annotations

import math

from servobus.errors import ArgumentRangeError, ConnectionLost, ServobusError


def finite(name: str, value: object) -> float:
    """A finite number (of seconds, as the messages say)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ArgumentRangeError(f"{name} must be a number of seconds, got {value!r}")
    number = float(value)
    if math.isnan(number) or math.isinf(number):
        raise ArgumentRangeError(f"{name}={value!r} must be a finite number of seconds")
    return number


def positive(name: str, value: object, unit: str) -> float:
    """A finite number > 0 in ``unit`` (e.g. a peak current in A)."""
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or not math.isfinite(float(value)) or float(value) <= 0:
        raise ArgumentRangeError(f"{name}={value!r} must be a finite number of {unit} > 0")
    return float(value)


def seconds(name: str, value: object) -> float:
    """A deadline or period: a finite number > 0."""
    number = finite(name, value)
    if number <= 0:
        raise ArgumentRangeError(f"{name}={value!r} must be > 0 seconds")
    return number


def optional_seconds(name: str, value: object) -> float | None:
    """``None`` (use the default) or :func:`seconds`."""
    return None if value is None else seconds(name, value)


def non_negative_seconds(name: str, value: object) -> float:
    """A margin or interval that may be 0 (off): a finite number >= 0."""
    number = finite(name, value)
    if number < 0:
        raise ArgumentRangeError(f"{name}={value!r} must be >= 0 seconds")
    return number


def count(name: str, value: object) -> int:
    """A retry count: an int >= 0 (not a bool, not a float)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ArgumentRangeError(f"{name} must be an integer >= 0, got {value!r}")
    if value < 0:
        raise ArgumentRangeError(f"{name}={value} must be >= 0")
    return value


def optional_count(name: str, value: object) -> int | None:
    return None if value is None else count(name, value)


def positive_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise ArgumentRangeError(f"{name} must be a positive integer, got {value!r}")
    return value


def param_name(name: object) -> str:
    """A parameter name must be a string before it is looked up in the table."""
    if not isinstance(name, str):
        raise ArgumentRangeError(f"parameter name must be a string, got {name!r}")
    return name


def data_bytes(name: str, value: object, length: int) -> bytes:
    """Exactly ``length`` bytes (bytes, bytearray or memoryview; not str, not ints)."""
    if not isinstance(value, bytes | bytearray | memoryview):
        raise ArgumentRangeError(
            f"{name} takes exactly {length} bytes (bytes/bytearray), got {value!r}")
    data = bytes(value)
    if len(data) != length:
        raise ArgumentRangeError(f"{name} takes exactly {length} bytes, got {len(data)}")
    return data


def lost(exc: BaseException, what: str) -> BaseException:
    """What a client raises for ``exc`` met while talking to the medium.

    Transports raise ConnectionLost already; a builtin ``ConnectionError``/``OSError`` from a
    third-party stream or bus (``BrokenPipeError``, ``ConnectionResetError``...) becomes one,
    so ``except ServobusError`` sees every dead link. Timeouts and servobus errors pass as
    they are (``TimeoutError`` is an ``OSError`` too).
    """
    if isinstance(exc, ServobusError | TimeoutError) or not isinstance(exc, OSError):
        return exc
    return ConnectionLost(f"{what}: {exc}")
