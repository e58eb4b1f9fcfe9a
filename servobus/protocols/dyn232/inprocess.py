"""In-process virtual DYN232M line as a ByteStream: what ``sim://dyn2`` URLs open.

``open_sim_stream()`` builds drives, a :class:`Dyn232Line` and a :class:`LineRunner` on the
current event loop (started lazily on first use, so it may be created before the loop runs)
and returns a :class:`SimByteStream`. The stream behaves like a serial port wired to the line:
paced at 38400 8N1 unless ``paced=False`` (``fast=1``), drives in wall-clock time.

URL form (parsed by :func:`parse_sim_url`)::

    sim://dyn2                      one drive with the id the caller asks for (connect()'s
                                    drive_id; the factory id 0 otherwise), paced
    sim://dyn2?ids=1,2,3&fast=1     three drives, unpaced
    sim://dyn2?state=/tmp/e.json    EEPROM kept in a JSON file (see EepromStore)
    sim://dyn2?model=DYN2-T1        motor/drive model (servobus.families.dmm.units.MODELS)

``dc2`` and ``dyn4`` are accepted as aliases of ``dyn2`` (same protocol, docs/dyn232.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, urlsplit

from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.device import Dyn232Line
from servobus.protocols.dyn232.pacing import HostPort, LineRunner
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.fleet import make_drives, parse_drive_ids
from servobus.transport.base import Direction
from servobus.transport.buffered import PushInput

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis

SIM_KINDS = ("dyn232", "dyn2", "dc2", "dyn4")
_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")


@dataclass(frozen=True)
class SimUrl:
    kind: str = "dyn2"
    ids: tuple[int, ...] = (c.FACTORY_ID,)
    paced: bool = True
    state: str | None = None
    model: str = U.DEFAULT_MODEL




def _flag(name: str, text: str) -> bool:
    low = text.lower()
    if low in _TRUE:
        return True
    if low in _FALSE:
        return False
    raise ArgumentRangeError(f"{name}={text!r}: expected 1/0, true/false")


def parse_sim_url(url: str, default_id: int = c.FACTORY_ID) -> SimUrl:
    """Parse ``sim://dyn2?ids=1,2&fast=1&state=FILE&model=NAME``.

    Without ``ids`` the line has one drive with ``default_id`` (servobus decision:
    ``connect("sim://dyn2", drive_id=1)`` finds a drive 1, as a user who asks for drive 1 of
    "the built-in drive" means); an id outside 0..63 falls back to the factory id.
    """
    parts = urlsplit(url)
    if parts.scheme != "sim":
        raise ArgumentRangeError(f"not a sim:// URL: {url!r}")
    kind = (parts.netloc or parts.path.lstrip("/") or "dyn2").lower()
    if kind not in SIM_KINDS:
        raise ArgumentRangeError(f"unknown virtual drive {kind!r} in {url!r}; known: "
                                 f"{', '.join(SIM_KINDS)}")
    query = {k: v[-1] for k, v in parse_qs(parts.query, keep_blank_values=True).items()}
    unknown = set(query) - {"ids", "fast", "paced", "state", "model"}
    if unknown:
        raise ArgumentRangeError(f"unknown sim URL option(s) {sorted(unknown)} in {url!r}")
    paced = True
    if "paced" in query:
        paced = _flag("paced", query["paced"])
    if "fast" in query:
        paced = not _flag("fast", query["fast"])
    model = query.get("model", U.DEFAULT_MODEL)
    if model not in U.MODELS:
        raise ArgumentRangeError(f"unknown model {model!r}; known: {', '.join(U.MODELS)}")
    if "ids" in query:
        ids = parse_drive_ids(query["ids"])
    else:
        ids = (default_id if 0 <= default_id <= c.MAX_DRIVE_ID else c.FACTORY_ID,)
    return SimUrl(kind=kind, ids=ids,
                  paced=paced, state=query.get("state") or None, model=model)




class SimByteStream(PushInput):
    """A ByteStream wired to an in-process virtual line (``transport.base.PushByteStream``).

    With a receiver installed, each reply is handed to it at its release time, from the
    line's release task (paced) or from within ``write()`` (unpaced): no reader to wake.
    """

    closed_text = "sim stream is closed"

    def __init__(self, runner: LineRunner) -> None:
        super().__init__()
        self.runner = runner
        self.line = runner.line
        self.drives: list[VirtualDrive] = runner.line.drives
        self._port: HostPort = runner.open_port(self._received)

    async def write(self, data: bytes) -> None:
        if self._closed:
            raise ConnectionError("sim stream is closed")
        data = bytes(data)
        if self._traces:
            self._trace(Direction.TX, data)
        self.runner.submit(self._port, data)  # starts the runner on first use

    def _before_wait(self) -> None:
        self.runner.start()  # a read() before any write() still runs the line

    async def close(self) -> None:
        if not self._mark_closed():  # wakes a pending read (ConnectionError), the receiver
            return
        self._port.closed = True
        await self.runner.close()

    @property
    def in_waiting(self) -> int:
        return len(self._buf)


def open_sim_stream(
    kind: str = "dyn2",
    *,
    ids: Sequence[int] = (c.FACTORY_ID,),
    paced: bool = True,
    drives: Sequence[VirtualDrive] | None = None,
    state: str | None = None,
    model: str = U.DEFAULT_MODEL,
) -> SimByteStream:
    """An in-process virtual line. ``drives`` (if given) replaces ``ids``/``state``/``model``."""
    if kind.lower() not in SIM_KINDS:
        raise ArgumentRangeError(f"unknown virtual drive {kind!r}; known: {', '.join(SIM_KINDS)}")
    if drives is None:
        parse_drive_ids(",".join(str(i) for i in ids))  # same validation as URLs
        drives = make_drives(ids, state=state, model=model)
    return SimByteStream(LineRunner(Dyn232Line(drives), paced=paced))


def open_sim_url(url: str, *, drives: Sequence[VirtualDrive] | None = None) -> SimByteStream:
    """``open_sim_stream`` from a ``sim://`` URL."""
    u = parse_sim_url(url)
    return open_sim_stream(u.kind, ids=u.ids, paced=u.paced, drives=drives, state=u.state,
                           model=u.model)


SIM_OPTIONS: dict[str, type] = {
    "ids": str, "fast": bool, "paced": bool, "state": str, "model": str,
    "timeout": float, "retries": int, "turnaround_s": float, "query_interval_s": float,
    "eeprom_guard": object, "late_reply_s": float,
}


async def open_sim_axis(url: DriveUrl, *, drive_id: int | None = None,
                        **keywords: object) -> AsyncAxis:
    """``sim://dyn232``: an Axis on an in-process virtual line (registered in ``SIM``).

    Without ``ids`` the line holds one drive with the id asked for (the factory id 0 when
    none is), so ``connect("sim://dyn232", drive_id=3)`` just works.
    """
    from servobus.protocols.dyn232.axis import Dyn232Axis
    from servobus.protocols.dyn232.client import AsyncDyn232Client
    from servobus.protocols.dyn232.commands import check_drive_id

    options = merge_options(url, dict(keywords), SIM_OPTIONS)
    if drive_id is not None:
        check_drive_id(drive_id)
    ids_text = options.pop("ids", None)
    ids = parse_drive_ids(str(ids_text)) if ids_text is not None else (
        (c.FACTORY_ID,) if drive_id is None else (drive_id,))
    paced = not bool(options.pop("fast", False)) and bool(options.pop("paced", True))
    model = str(options.pop("model", U.DEFAULT_MODEL))
    if model not in U.MODELS:
        raise ArgumentRangeError(f"unknown model {model!r}; known: {', '.join(U.MODELS)}")
    state = options.pop("state", None)
    stream = open_sim_stream("dyn2", ids=ids, paced=paced, model=model,
                             state=str(state) if state else None)
    client = AsyncDyn232Client(stream, **options)  # type: ignore[arg-type]
    return Dyn232Axis(client, ids[0] if drive_id is None else drive_id)
