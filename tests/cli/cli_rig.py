"""What the in-process CLI tests share: ``run`` (``servobus ARGS`` in this process), the
``no_env`` fixture (no SERVOBUS_* variable of the developer's shell reaches a test) and the
``on_connect`` fixture (actions run on each Axis the CLI opens). A test module imports the
fixtures by name: ``from cli_rig import no_env as no_env``."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator
from typing import Any

import pytest

import servobus.machine.links as links
from servobus import axis as axis_package
from servobus.axis import Axis
from servobus.axis.base import AsyncAxis
from servobus.cli.main import main

#: A machine of one mm axis with soft limits (DMM, serial) and one deg axis without (YZ-AIM,
#: CAN), on virtual drives.
CELL = """\
name = "cell"
[axes.x]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]
[axes.c]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
"""

#: An async action on each AsyncAxis the CLI opens.
Action = Callable[[AsyncAxis], Awaitable[Any]]
ENV = ("SERVOBUS_MACHINE", "SERVOBUS_URL", "SERVOBUS_ID")


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """``servobus ARGS`` in this process: exit code, stdout, stderr."""
    with pytest.raises(SystemExit) as info:
        main(list(args))
    out, err = capsys.readouterr()
    code = info.value.code
    return code if isinstance(code, int) else 0, out, err


@pytest.fixture(autouse=True)
def no_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ENV:
        monkeypatch.delenv(name, raising=False)


@pytest.fixture
def on_connect(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Action]]:
    """Async actions run on each AsyncAxis the CLI opens, one drive or a machine link (the
    sync facade runs them on its loop)."""
    actions: list[Action] = []
    real_sync, real_async = axis_package.connect, links.connect_async

    def connect(url: str, **options: Any) -> Axis:
        ax = real_sync(url, **options)
        for action in actions:
            ax._call(lambda a=action: a(ax.core))  # type: ignore[attr-defined,misc]
        return ax

    async def connect_async(url: str | None = None, **options: Any) -> AsyncAxis:
        ax = await real_async(url, **options)
        for action in actions:
            await action(ax)
        return ax

    monkeypatch.setattr(axis_package, "connect", connect)
    monkeypatch.setattr(links, "connect_async", connect_async)
    yield actions
