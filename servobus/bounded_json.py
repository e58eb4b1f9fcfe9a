"""JSON from outside, bounded before anything uses it: the GUI's and the gateway's parser.

Decisions (a server that moves machines must not be stalled or killed by one message):

* Size: a caller may pass ``max_bytes``; larger text is refused before it is decoded. The
  servers also bound sizes on the wire (servobus.gui.limits, the MQTT gate's payload limit).
* Nesting deeper than ``max_depth`` (default :data:`MAX_DEPTH`) is refused before the text
  is parsed: no parse recurses (Python's own parser raises ``RecursionError`` near 1,000
  levels), and the depth is found by C-speed passes over the text (:func:`depth`), so a
  maximal input costs a few milliseconds.
* Numbers are JSON numbers a double holds: a number beyond a double's range (``1e400``,
  ``-1e999``, a 400-digit integer) is refused while parsing (``json.loads``'s
  ``parse_float``/``parse_int`` hooks), never turned into ``inf`` or into an integer that
  raises ``OverflowError`` where it is later used as a float. An integer literal longer
  than :data:`MAX_INT_DIGITS` is refused before Python converts it (Python's own limit,
  ``sys.get_int_max_str_digits()``, 4300 by default, would raise a plain ``ValueError``).
  Integers keep their type (an axis number stays an ``int``).
* ``NaN``, ``Infinity`` and ``-Infinity`` (Python's extensions, not JSON) are refused: no
  input of the GUI or of an MQTT command has a use for them (the page's ``JSON.stringify``
  never writes them, the gateway's numbers must be finite).

Every refusal is a :class:`servobus.errors.JsonRefused` saying what is wrong. This module
imports nothing of servobus but ``errors``, so every front end may use it.
"""

from __future__ import annotations

import itertools
import json
import math
import re

from servobus.errors import JsonRefused

MAX_DEPTH = 32
#: The longest integer literal accepted: 309 digits reach past a double's largest value
#: (1.8e308), so every integer a double holds fits.
MAX_INT_DIGITS = 309

_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")
_STEP = {"[": 1, "{": 1, "]": -1, "}": -1}


def depth(text: str) -> int:
    """The deepest nesting of arrays and objects in JSON ``text`` (strings skipped)."""
    brackets = _NOT_BRACKET.sub("", _STRING.sub("", text))
    return max(itertools.accumulate(map(_STEP.__getitem__, brackets)), default=0)


def _int(literal: str) -> int:
    digits = len(literal.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise JsonRefused(f"the integer {excerpt(literal, 12)} ({digits} digits) is beyond a "
                          "double's range")
    value = int(literal)
    try:
        float(value)
    except OverflowError:
        raise JsonRefused(f"the integer {excerpt(literal, 12)} is beyond a double's range") \
            from None
    return value


def _float(literal: str) -> float:
    value = float(literal)
    if not math.isfinite(value):
        raise JsonRefused(f"the number {excerpt(literal, 12)} is beyond a double's range")
    return value


def _constant(name: str) -> object:
    raise JsonRefused(f"{name} is not a JSON number")


_DECODER = json.JSONDecoder(parse_int=_int, parse_float=_float, parse_constant=_constant)


def loads(text: str | bytes, *, max_depth: int = MAX_DEPTH, max_bytes: int | None = None
          ) -> object:
    """``json.loads`` with size, nesting and numbers bounded; JsonRefused says why not."""
    if max_bytes is not None and _size(text) > max_bytes:
        raise JsonRefused(f"JSON text of more than {max_bytes} bytes")
    if isinstance(text, bytes | bytearray):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise JsonRefused("not JSON: not UTF-8 text") from None
    if depth(text) > max_depth:
        raise JsonRefused(f"JSON nested deeper than {max_depth} levels")
    try:
        return _DECODER.decode(text)
    except JsonRefused:
        raise
    except (ValueError, RecursionError) as exc:
        raise JsonRefused(f"not JSON: {exc}") from None


def _size(text: str | bytes) -> int:
    return len(text) if isinstance(text, bytes | bytearray) else \
        len(text.encode("utf-8", "replace"))


def excerpt(text: str, size: int = 40) -> str:
    """The start of a text, to name it in an error."""
    return text if len(text) <= size else text[:size] + "..."
