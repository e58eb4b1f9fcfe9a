"""URL scheme registry (like python-can's interface table): scheme -> lazily imported opener.

Providers declare their schemes; nothing here names a protocol. A provider is a module with

    SCHEMES: Mapping[str, str]   # scheme -> "module:function" of an opener
    async def opener(url: DriveUrl, *, drive_id: int | None, **options) -> AsyncAxis

Providers are every subpackage of :mod:`servobus.protocols` (its ``__init__`` stays light:
it declares ``SCHEMES`` and imports nothing heavy), the simulator's ``servobus.sim.schemes``
(``sim://``; a host client never imports the simulator unless a ``sim://`` URL is opened),
and third-party packages through the ``servobus.schemes`` entry-point group (each entry
point names a provider module). The empty scheme ``""`` is the bare serial port
(``/dev/ttyUSB0``, ``COM3``); pyserial URL schemes (``socket``, ``loop`` ...) are claimed by
the protocol that serves bare serial ports, in its ``SERIAL_SCHEMES`` table: they open, but
an error message lists servobus's own schemes only (``SCHEMES``), and an unknown scheme
suggests the one it resembles (difflib).
"""

from __future__ import annotations

import difflib
import importlib
import pkgutil
from collections.abc import Awaitable, Callable, Mapping
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, cast

from servobus.errors import UnknownScheme

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis
    from servobus.axis.url import DriveUrl

Opener = Callable[..., Awaitable["AsyncAxis"]]

BUILTIN_PROVIDERS: tuple[str, ...] = ("servobus.sim.schemes",)
PROTOCOL_PACKAGE = "servobus.protocols"
ENTRY_POINT_GROUP = "servobus.schemes"

_extra: dict[str, str] = {}


def register(scheme: str, target: str) -> None:
    """Add (or replace) a scheme at run time: ``target`` is ``"module:function"``."""
    _extra[scheme.lower()] = target


def _provider_modules() -> list[str]:
    names = list(BUILTIN_PROVIDERS)
    package = importlib.import_module(PROTOCOL_PACKAGE)
    names += [f"{PROTOCOL_PACKAGE}.{m.name}" for m in pkgutil.iter_modules(package.__path__)
              if m.ispkg]
    names += [ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)]
    return names


_tables: dict[str, dict[str, str]] = {}


def provided(attribute: str) -> dict[str, str]:
    """Merge one declared table (``SCHEMES``, ``SIM``) over every provider, first wins."""
    table = _tables.get(attribute)
    if table is None:
        table = {}
        for name in _provider_modules():
            module = importlib.import_module(name)
            declared = cast(Mapping[str, str], getattr(module, attribute, {}))
            for key, target in declared.items():
                table.setdefault(key.lower(), target)
        _tables[attribute] = table
    return table


def provided_list(attribute: str) -> list[str]:
    """Single values a provider declares (``CLI = "module:register"``), in provider order."""
    found: list[str] = []
    for name in _provider_modules():
        value = getattr(importlib.import_module(name), attribute, None)
        if isinstance(value, str):
            found.append(value)
    return found


def schemes() -> dict[str, str]:
    """Every known scheme -> its opener target (providers are imported once, lightly)."""
    return {**provided("SERIAL_SCHEMES"), **provided("SCHEMES"), **_extra}


def own_schemes() -> list[str]:
    """servobus's own schemes (not the pyserial URLs a serial protocol also takes), sorted."""
    return sorted({*provided("SCHEMES"), *_extra} - {""})


def load(target: str) -> Any:
    """Import ``"module:attribute"`` and return the attribute."""
    module_name, _, attr = target.partition(":")
    return getattr(importlib.import_module(module_name), attr)


def scheme_list() -> str:
    """The schemes for an error message: servobus's own, then the bare serial port."""
    return ", ".join(own_schemes()) + ", or a bare serial port (/dev/ttyUSB0, COM3)"


def resembling(url: DriveUrl) -> str | None:
    """``url`` with its scheme replaced by the known one it resembles most, if any."""
    close = difflib.get_close_matches(url.scheme, own_schemes(), n=1, cutoff=0.6)
    if not close:
        return None
    head = url.raw.split(":", 1)[0]
    return close[0] + head[len(url.scheme):] + url.raw[len(head):]


def lookup(url: DriveUrl) -> Opener:
    """The opener for ``url``: ``scheme+transport`` first, then ``scheme``."""
    table = schemes()
    key = f"{url.scheme}+{url.transport}" if url.transport else url.scheme
    target = table.get(key) or table.get(url.scheme if url.transport else key)
    if target is None:
        suggestion = resembling(url)
        hint = f" (did you mean {suggestion}?)" if suggestion else ""
        raise UnknownScheme(f"unknown drive URL scheme {url.scheme!r} in {url.raw!r}{hint}; "
                            f"known: {scheme_list()}", suggestion)
    return cast(Opener, load(target))


def protocol_of(url: DriveUrl) -> str | None:
    """The protocol package serving ``url`` (``dyn232`` for ``/dev/ttyUSB0``), if any.

    ``sim://<name>`` counts as the protocol of that virtual drive.
    """
    if url.scheme == "sim":
        target = provided("SIM").get(url.target.strip("/").lower() or "dyn232")
    else:
        table = schemes()
        key = f"{url.scheme}+{url.transport}" if url.transport else url.scheme
        target = table.get(key) or table.get(url.scheme)
    if target is None:
        return None
    module = target.partition(":")[0]
    prefix = PROTOCOL_PACKAGE + "."
    return module[len(prefix):].split(".")[0] if module.startswith(prefix) else None
