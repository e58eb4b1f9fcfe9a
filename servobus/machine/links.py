"""The links of a machine: axes with the same URL share one connection, opened once.

The first axis of a URL opens it (``connect_async``); the others are its siblings
(``AsyncAxis.sibling``), as the GUI fleet does. On ``sim://`` the in-process line or bus is
built with every id of the machine on it (``ids=``) unless the URL names its own, so two
axes on one ``sim://`` URL share one virtual line. URLs are compared as written (after
stripping blanks): two spellings of one port are two links, which the port refuses.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence

from servobus.axis.base import AsyncAxis
from servobus.axis.connect import connect_async
from servobus.axis.url import parse_url
from servobus.errors import ArgumentRangeError, MachineFileError, MachineLinkError
from servobus.machine.axis import AsyncMachineAxis
from servobus.machine.config import link_key


class Link:
    """One URL and the machine axes on it."""

    def __init__(self, url: str, axes: Sequence[AsyncMachineAxis], source: str) -> None:
        self.url = url
        self.axes = list(axes)
        self.source = source
        self.owner: AsyncAxis | None = None
        #: When the link last came back, and how many times in a row it dropped again
        #: within STABLE_S of that (AsyncMachine._recover).
        self.up_since = 0.0
        self.quick_drops = 0
        #: True while a reopened link's first reads run: a drop then fails the try quietly.
        self.verifying = False

    @property
    def online(self) -> bool:
        return self.owner is not None

    def _options(self) -> dict[str, object]:
        parsed = parse_url(self.url)
        ids = [a.spec.drive_id for a in self.axes if a.spec.drive_id is not None]
        if parsed.scheme == "sim" and "ids" not in parsed.options and ids:
            return {"ids": ",".join(str(i) for i in ids)}
        return {}

    async def open(self) -> None:
        """Open the connection and every axis on it; on failure close what was opened and
        raise MachineLinkError (MachineFileError for a URL that is no drive URL)."""
        first = self.axes[0]
        try:
            owner = await connect_async(self.url, drive_id=first.spec.drive_id,
                                        **self._options())
        except ArgumentRangeError as exc:
            raise MachineFileError(f"{self.source}: axis {first.name}: url: {exc}") from exc
        except Exception as exc:
            raise MachineLinkError(f"{self.source}: axis {first.name}: cannot open "
                                   f"{self.url}: {exc}") from exc
        opened = [owner]
        try:
            for axis in self.axes[1:]:
                try:
                    sib = await owner.sibling(self._id(axis))
                except ArgumentRangeError as exc:
                    raise MachineFileError(f"{self.source}: axis {axis.name}: id: {exc}") \
                        from exc
                if sib.capture_source is None:
                    sib.capture_source = owner.capture_source  # same connection
                if sib.io_source is None:
                    sib.io_source = owner.io_source
                opened.append(sib)
        except BaseException:
            for core in reversed(opened):
                with contextlib.suppress(Exception):
                    await core.close()
            raise
        self.owner = owner
        for axis, core in zip(self.axes, opened, strict=True):
            core.continuous = axis.spec.continuous
            axis.axis = core
            axis.last_error = None

    def cores(self) -> list[AsyncAxis]:
        """The Axes of the link while it is online (the owner's first)."""
        return [a.axis for a in self.axes if a.axis is not None]

    def take_offline(self, err: BaseException) -> list[AsyncAxis]:
        """The link dropped: every axis offline (AsyncMachineAxis.went_offline); the Axes
        it had, for the caller to close."""
        cores = self.cores()
        self.owner = None
        for axis in self.axes:
            axis.went_offline(err)
        return cores

    def _id(self, axis: AsyncMachineAxis) -> int:
        if axis.spec.drive_id is None:  # two axes on one link need ids (config checks it)
            raise MachineFileError(f"{self.source}: axis {axis.name}: id: missing: axes that "
                                   f"share {self.url} each need an id")
        return axis.spec.drive_id

    def mark_offline(self, exc: BaseException) -> None:
        for axis in self.axes:
            axis.axis = None
            axis.last_error = exc

    async def close(self) -> None:
        """Siblings first, the connection's owner last; the axes go offline."""
        cores = [a.axis for a in self.axes if a.axis is not None]
        for axis in self.axes:
            axis.axis = None
        self.owner = None
        for core in reversed(cores):
            with contextlib.suppress(Exception):
                await core.close()


def group_links(axes: Sequence[AsyncMachineAxis], source: str) -> list[Link]:
    """One Link per URL (its spellings are one: config.link_key), in the order the file first
    names it; the link opens the first spelling."""
    by_key: dict[str, list[AsyncMachineAxis]] = {}
    for axis in axes:
        by_key.setdefault(link_key(axis.url), []).append(axis)
    return [Link(members[0].url, members, source) for members in by_key.values()]
