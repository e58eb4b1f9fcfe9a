"""Machine files for the machine tests: mixed links on in-process virtual drives."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

#: The machine CLI tests' ``run`` fixture (tests/machine/conftest.py): args -> (exit code,
#: stdout, stderr).
Run = Callable[..., tuple[int, str, str]]

#: Two DMM axes on one virtual RS-485 line, a YZ-AIM motor on a virtual CAN bus.
MIXED = """\
name = "test-cell"

[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]
speed = 50.0

[axes.y]
url = "sim://dyn232?fast=1"
id = 2
unit = "mm"
per_rev = 5.0
direction = -1

[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
limits = [-720.0, 720.0]
"""


def write_machine(tmp_path: Path, text: str = MIXED, name: str = "m.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


#: ``flaky://`` (registered by the tests): fails while ``FLAKY["down"]``, else opens the
#: in-process virtual DYN232M line - a link that comes up later, without a real port.
FLAKY: dict[str, object] = {"down": True, "attempts": 0}


async def flaky_open(url: object, *, drive_id: int | None = None, **options: object) -> object:
    from servobus.axis.connect import connect_async

    FLAKY["attempts"] = int(str(FLAKY["attempts"])) + 1
    if FLAKY["down"]:
        raise ConnectionRefusedError("nothing listens on flaky://")
    return await connect_async("sim://dyn232?fast=1", drive_id=drive_id, **options)
