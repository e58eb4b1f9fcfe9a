"""Machine files for the machine tests: mixed links on in-process virtual drives."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from servobus.cli.main import main

#: The machine CLI tests' ``run`` fixture (below): args -> (exit code, stdout, stderr).
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


@pytest.fixture
def run(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> Run:
    """The ``servobus`` command in this process, without the environment's machine or
    URL: ``run(*args)`` gives (exit code, stdout, stderr). A test module imports it."""
    monkeypatch.delenv("SERVOBUS_MACHINE", raising=False)
    monkeypatch.delenv("SERVOBUS_URL", raising=False)

    def go(*args: str) -> tuple[int, str, str]:
        capsys.readouterr()
        with pytest.raises(SystemExit) as info:
            main(list(args))
        out, err = capsys.readouterr()
        return int(info.value.code or 0), out, err

    return go
