"""Fixtures of the machine tests."""

from __future__ import annotations

import pytest
from machine_rig import Run

from servobus.cli.main import main


@pytest.fixture
def run(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> Run:
    """The ``servobus`` command in this process, without the environment's machine or
    URL: ``run(*args)`` gives (exit code, stdout, stderr)."""
    monkeypatch.delenv("SERVOBUS_MACHINE", raising=False)
    monkeypatch.delenv("SERVOBUS_URL", raising=False)

    def go(*args: str) -> tuple[int, str, str]:
        capsys.readouterr()
        with pytest.raises(SystemExit) as info:
            main(list(args))
        out, err = capsys.readouterr()
        return int(info.value.code or 0), out, err

    return go
