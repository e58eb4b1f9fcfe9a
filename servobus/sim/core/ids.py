"""The drive ids a simulator serves, as a user lists them (``--ids 1,2,3``, ``?ids=1,2``)."""

from __future__ import annotations

from servobus.errors import ArgumentRangeError


def parse_ids(text: str, *, min_id: int, max_id: int) -> tuple[int, ...]:
    """``"1,2,3"`` -> (1, 2, 3); each in ``min_id..max_id``, no duplicates."""
    try:
        ids = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise ArgumentRangeError(f"drive ids must be integers, got {text!r}") from None
    if not ids:
        raise ArgumentRangeError("at least one drive id is needed")
    bad = [i for i in ids if not min_id <= i <= max_id]
    if bad:
        raise ArgumentRangeError(f"drive ids {bad} are outside {min_id}..{max_id}")
    if len(set(ids)) != len(ids):
        raise ArgumentRangeError(f"duplicate drive ids in {text!r}")
    return ids
