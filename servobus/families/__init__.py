"""Device-family models: parameter tables, status decoding, counts per revolution.

:data:`FAMILIES` names every family's model object (imported lazily by :func:`family`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from servobus.axis.types import Family

FAMILIES: dict[str, str] = {
    "dmm-dyn2": "servobus.families.dmm.family:DYN2",
    "dmm-dyn5": "servobus.families.dyn5.family:DYN5",
    "yzaim": "servobus.families.yzaim.family:YZAIM",
}


def family(name: str) -> Family:
    """The Family called ``name``; ArgumentRangeError naming the known ones."""
    from servobus.errors import ArgumentRangeError

    target = FAMILIES.get(name)
    if target is None:
        raise ArgumentRangeError(f"unknown drive family {name!r}; known: {', '.join(FAMILIES)}")
    module, _, attr = target.partition(":")
    found: Family = getattr(importlib.import_module(module), attr)
    return found
