"""Argument checks shared by every client: options and per-call knobs, before anything is sent.

Codes, ranges and units of the drives live in the codecs and ``drive.params``; this module
only checks the host-side numbers (deadlines, retry counts, intervals) and the plain Python
types the ``make_*`` builders take. Every failure is an ArgumentRangeError naming the
argument and the value, and nothing has been sent when it is raised.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping

from servobus.axis.eeprom_guard import EepromGuard
from servobus.errors import ArgumentRangeError, ConnectionLost, ServobusError


def _real(name: str, value: object) -> float:
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
    number = _real(name, value)
    if number <= 0:
        raise ArgumentRangeError(f"{name}={value!r} must be > 0 seconds")
    return number


def optional_seconds(name: str, value: object) -> float | None:
    """``None`` (use the default) or :func:`seconds`."""
    return None if value is None else seconds(name, value)


def non_negative_seconds(name: str, value: object) -> float:
    """A margin or interval that may be 0 (off): a finite number >= 0."""
    number = _real(name, value)
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


# ---------------------------------------------------------------- connect options
def _guard(name: str, value: object) -> object:
    if value is not None and not isinstance(value, EepromGuard):
        raise ArgumentRangeError(f"{name} must be an EepromGuard, got {value!r}")
    return value


def _callback(name: str, value: object) -> object:
    if value is not None and not callable(value):
        raise ArgumentRangeError(f"{name} must be callable, got {value!r}")
    return value


def _transport(name: str, value: object) -> object:
    if value not in ("auto", "tcp", "pyserial"):
        raise ArgumentRangeError(f"{name}={value!r}: use 'auto', 'tcp' or 'pyserial'")
    return value


def _amperes(name: str, value: object) -> float:
    return positive(name, value, "A")


#: The connect options every protocol shares, by name, checked the same way everywhere.
#: Decision: ``timeout=None`` means the protocol's default; no other option takes None
#: except the optional objects (``eeprom_guard``, ``on_alarm``).
OPTION_CHECKS: dict[str, Callable[[str, object], object]] = {
    "timeout": optional_seconds, "connect_timeout": seconds, "reset_timeout": seconds,
    "retries": count, "turnaround_s": non_negative_seconds,
    "query_interval_s": non_negative_seconds, "late_reply_s": non_negative_seconds,
    "frame_gap_s": non_negative_seconds, "reset_downtime_s": non_negative_seconds,
    "baud": positive_int, "bitrate": positive_int, "max_in_flight": positive_int,
    "peak_current_a": _amperes, "eeprom_guard": _guard, "on_alarm": _callback,
    "transport": _transport,
}


def connect_options(options: Mapping[str, object], types: Mapping[str, type]) -> None:
    """Check every connect option (URL query and keywords, merged) before anything is opened.

    Shared options are checked by name (:data:`OPTION_CHECKS`); a protocol's own options by
    their declared type: ``str`` takes a string (a path-like too), ``bool`` a bool or 0/1,
    ``int`` an integer, ``float`` a finite number. ArgumentRangeError names the option.
    """
    for name, value in options.items():
        check = OPTION_CHECKS.get(name)
        if check is not None:
            check(name, value)
            continue
        kind = types.get(name, object)
        if kind is str and not isinstance(value, str | os.PathLike):
            raise ArgumentRangeError(f"{name} must be a string, got {value!r}")
        if kind is bool and (not isinstance(value, int) or value not in (0, 1)):
            raise ArgumentRangeError(f"{name} must be true or false, got {value!r}")
        if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
            raise ArgumentRangeError(f"{name} must be an integer, got {value!r}")
        if kind is float:
            _real(name, value)
