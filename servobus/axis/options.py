"""The connect options every protocol shares, checked by name before anything is opened.

A URL's query options and ``connect()``'s keywords merge
(:func:`servobus.axis.url.merge_options`) and land here: the shared ones are checked by
name (:data:`OPTION_CHECKS`), a protocol's own by the type its opener declares.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping

from servobus import checks
from servobus.errors import ArgumentRangeError
from servobus.link.eeprom_guard import EepromGuard


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
    return checks.positive(name, value, "A")


#: The connect options every protocol shares, by name, checked the same way everywhere.
#: Decision: ``timeout=None`` means the protocol's default; no other option takes None
#: except the optional objects (``eeprom_guard``, ``on_alarm``).
C = checks
OPTION_CHECKS: dict[str, Callable[[str, object], object]] = {
    "timeout": C.optional_seconds, "connect_timeout": C.seconds, "reset_timeout": C.seconds,
    "retries": C.count, "turnaround_s": C.non_negative_seconds,
    "query_interval_s": C.non_negative_seconds, "late_reply_s": C.non_negative_seconds,
    "frame_gap_s": C.non_negative_seconds, "reset_downtime_s": C.non_negative_seconds,
    "baud": C.positive_int, "bitrate": C.positive_int, "max_in_flight": C.positive_int,
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
            checks.finite(name, value)
