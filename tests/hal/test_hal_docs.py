"""docs/linuxcnc.md's pin tables say what the component makes (servobus.hal.pins)."""

from __future__ import annotations

import re
from pathlib import Path

from servobus.hal.pins import AXIS_PINS, COMPONENT_PINS

DOC = Path(__file__).resolve().parents[2] / "docs" / "linuxcnc.md"
ROW = re.compile(r"^\| `(?:<name>\.)?([a-z-]+)` \| (float|bit|s32) \| (in|out) \|", re.M)


def test_the_pin_tables_match_the_component() -> None:
    documented = {(name, kind, direction) for name, kind, direction in ROW.findall(DOC.read_text())}
    made = {(p.name, p.kind, p.direction) for p in AXIS_PINS + COMPONENT_PINS}
    assert documented == made
