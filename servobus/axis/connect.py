"""connect() / connect_async(): one entry point for every protocol (docs/axis.md).

The URL names the protocol, transport and target (:mod:`servobus.axis.url`); the registry
(:mod:`servobus.axis.registry`) finds the protocol that serves it. This module knows no
protocol. ``url=None`` opens the built-in virtual drive, :data:`DEFAULT_URL`.

``drive_id=None`` means the protocol's default (its factory id); on ``sim://`` without
``?ids=`` the virtual drive takes the id that is asked for.
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType
from typing import Any

from servobus.axis import inline, registry
from servobus.axis.base import AsyncAxis
from servobus.axis.sync import Axis, LoopThread, Runner
from servobus.axis.url import DriveUrl, parse_url
from servobus.errors import ArgumentRangeError

DEFAULT_URL = "sim://dyn232"


async def connect_async(url: str | None = None, *, drive_id: int | None = None,
                        **options: Any) -> AsyncAxis:
    """Open the drive ``url`` names and return its AsyncAxis (close it when done).

    Options (keywords or ``?name=value`` in the URL; keywords win) are per protocol:
    docs/axis.md has the table. Every argument is checked before anything is opened.
    """
    parsed = parse_url(DEFAULT_URL if url is None else url)
    parsed, continuous = _continuous(parsed, options)
    opener = registry.lookup(parsed)
    axis = await opener(parsed, drive_id=drive_id, **options)
    axis.continuous = continuous
    return axis


def _continuous(parsed: DriveUrl, options: dict[str, Any]) -> tuple[DriveUrl, bool]:
    """Take ``continuous`` out of the options (keyword or ``?continuous=``, the keyword
    wins): it is the Axis's, not the protocol's. ``1``/``true``/``yes`` or ``0``/``false``/
    ``no``."""
    query = dict(parsed.options)
    raw: object = query.pop("continuous", False)
    raw = options.pop("continuous", raw)
    if len(query) != len(parsed.options):
        parsed = dataclasses.replace(parsed, options=MappingProxyType(query))
    if isinstance(raw, bool):
        return parsed, raw
    text = str(raw).strip().lower()
    if text in ("1", "true", "yes"):
        return parsed, True
    if text in ("0", "false", "no"):
        return parsed, False
    raise ArgumentRangeError(f"continuous must be 1 or 0 (true or false), got {raw!r}")


def connect(url: str | None = None, *, drive_id: int | None = None, **options: Any) -> Axis:
    """Synchronous :func:`connect_async`: the Axis runs on a private event loop - on the
    caller's thread where the protocol says its link needs no loop between calls
    (:mod:`servobus.axis.inline`), on a loop thread of its own otherwise."""
    parsed = parse_url(DEFAULT_URL if url is None else url)
    runner: Runner = (inline.InlineRunner() if inline.available() and registry.runs_inline(parsed)
                      else LoopThread())
    try:
        core = runner.run(connect_async(url, drive_id=drive_id, **options))
    except BaseException:
        runner.stop()
        raise
    return Axis(core, runner)
