"""servobus.bounded_json, the JSON reader of the GUI and the gateway (issue 30): nesting,
sizes and numbers are refused with a typed error before anything uses them."""

from __future__ import annotations

import json

import pytest

from servobus import bounded_json
from servobus.bounded_json import MAX_DEPTH, MAX_INT_DIGITS, depth, loads
from servobus.errors import JsonRefused, ServobusError

LARGEST_DOUBLE_INT = str(int(1.7976931348623157e308))  # 309 digits


@pytest.mark.parametrize("text,why", [
    ("1e400", "beyond a double's range"),
    ("-1e999", "beyond a double's range"),
    ('{"value": 1.5e309}', "beyond a double's range"),
    ("9" * 400, "400 digits"),
    ("-" + "9" * 400, "400 digits"),
    ("1" * 5000, "5000 digits"),  # past Python's own int max str digits (4300)
    ("1" + LARGEST_DOUBLE_INT[1:].replace("7", "9", 1), "beyond a double's range"),
    ("NaN", "NaN is not a JSON number"),
    ('{"ts": Infinity}', "Infinity is not a JSON number"),
    ("[-Infinity]", "-Infinity is not a JSON number"),
    ("[" * 1000 + "]" * 1000, f"nested deeper than {MAX_DEPTH} levels"),
    ("[" * 100_000, f"nested deeper than {MAX_DEPTH} levels"),
    ("{nope", "not JSON"),
    (b"\xff\xfe", "not UTF-8"),
], ids=["1e400", "-1e999", "float-in-object", "400-digits", "negative-400-digits",
        "5000-digits", "just-past-the-largest-double", "NaN", "Infinity", "-Infinity",
        "1000-deep", "100000-open", "not-json", "not-utf8"])
def test_refused_with_a_typed_error_naming_why(text: str | bytes, why: str) -> None:
    with pytest.raises(JsonRefused) as refused:
        loads(text)
    assert why in str(refused.value)
    assert isinstance(refused.value, ServobusError) and isinstance(refused.value, ValueError)


def test_what_a_double_holds_is_read_as_before() -> None:
    doc = loads('{"axis": 2, "rpm": -300, "x": [1.5, 1e308, -1e-400], "s": "[[[{{"}')
    assert doc == {"axis": 2, "rpm": -300, "x": [1.5, 1e308, -0.0], "s": "[[[{{"}
    assert isinstance(doc["axis"], int)  # type: ignore[index]
    assert loads(LARGEST_DOUBLE_INT) == int(LARGEST_DOUBLE_INT)
    assert len(LARGEST_DOUBLE_INT) == MAX_INT_DIGITS
    nested = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    assert loads(nested) == json.loads(nested) and depth(nested) == MAX_DEPTH


def test_a_size_bound_is_checked_before_decoding() -> None:
    assert loads(b"[1, 2]", max_bytes=6) == [1, 2]
    with pytest.raises(JsonRefused, match="more than 6 bytes"):
        loads(b"[1, 22]", max_bytes=6)
    with pytest.raises(JsonRefused, match="more than 6 bytes"):
        loads('"\u00e9\u00e9\u00e9"', max_bytes=6)  # 5 characters, 8 bytes of UTF-8


def test_the_excerpt_names_the_start_of_a_long_text() -> None:
    assert bounded_json.excerpt("short") == "short"
    assert bounded_json.excerpt("x" * 100) == "x" * 40 + "..."
