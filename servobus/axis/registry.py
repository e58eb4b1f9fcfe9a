"""URL scheme registry (like python-can's interface table): scheme -> lazily imported opener.

Providers declare what they offer; nothing here names a protocol. A protocol declares one
frozen :class:`~servobus.protocols.ProtocolSpec` as ``SPEC`` in its package ``__init__``
(its schemes and opener, its ``sim://`` virtual drive, CLI commands, sniff decoder,
parameters, family), each target a ``"module:attribute"`` string imported when used::

    async def opener(url: DriveUrl, *, drive_id: int | None, **options) -> AsyncAxis

Providers are every subpackage of :mod:`servobus.protocols` (its ``__init__`` stays light:
it declares ``SPEC`` and imports nothing heavy) and third-party packages through the
``servobus.schemes`` entry-point group (each entry point names a module declaring ``SPEC``;
one without is skipped, with one warning). ``sim://`` is the registry's own scheme
(:data:`BUILTIN_SCHEMES`, the simulator's ``servobus.sim.schemes``: a host client never
imports the simulator unless a ``sim://`` URL is opened); it opens the virtual drive a
spec's ``sim`` names. The empty scheme ``""`` is the bare serial port
(``/dev/ttyUSB0``, ``COM3``); pyserial URL schemes (``socket``, ``loop`` ...) are claimed by
the protocol that serves bare serial ports, in its spec's ``serial_schemes``: they open, but
an error message lists servobus's own schemes only (``schemes``), and an unknown scheme
suggests the one it resembles (difflib).
"""

from __future__ import annotations

import difflib
import importlib
import logging
import pkgutil
from collections.abc import Awaitable, Callable
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, cast

from servobus.errors import UnknownScheme
from servobus.protocols import ProtocolSpec

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis
    from servobus.axis.url import DriveUrl

log = logging.getLogger(__name__)

Opener = Callable[..., Awaitable["AsyncAxis"]]

#: Schemes of no protocol: ``sim://<name>`` opens the virtual drive a spec's ``sim`` names.
BUILTIN_SCHEMES: dict[str, str] = {"sim": "servobus.sim.schemes:open_axis"}
PROTOCOL_PACKAGE = "servobus.protocols"
ENTRY_POINT_GROUP = "servobus.schemes"

_extra: dict[str, str] = {}


def register(scheme: str, target: str) -> None:
    """Add (or replace) a scheme at run time: ``target`` is ``"module:function"``."""
    _extra[scheme.lower()] = target


def _provider_modules() -> list[str]:
    package = importlib.import_module(PROTOCOL_PACKAGE)
    names = [f"{PROTOCOL_PACKAGE}.{m.name}" for m in pkgutil.iter_modules(package.__path__)
              if m.ispkg]
    names += [ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)]
    return names


#: The tables the shared layers ask for, each derived from every ProtocolSpec.
_FROM_SPEC: dict[str, Callable[[ProtocolSpec], dict[str, str]]] = {
    "SCHEMES": lambda spec: dict.fromkeys(spec.schemes, spec.opener),
    "SERIAL_SCHEMES": lambda spec: dict.fromkeys(spec.serial_schemes, spec.opener),
    "SIM": lambda spec: dict.fromkeys(spec.sim_names, spec.sim) if spec.sim else {},
    "DECODERS": lambda spec: {spec.name: spec.decoder} if spec.decoder else {},
    "PARAMS": lambda spec: {spec.name: spec.params} if spec.params else {},
    "FAMILIES": lambda spec: {spec.name: spec.family},
    "SHORTCUTS": lambda spec: dict(spec.shortcuts),
}

_specs: dict[str, ProtocolSpec] | None = None
_tables: dict[str, dict[str, str]] = {}


def _spec_of(module: object) -> ProtocolSpec | None:
    spec = getattr(module, "SPEC", None)
    return spec if isinstance(spec, ProtocolSpec) else None


def specs() -> dict[str, ProtocolSpec]:
    """Every protocol's spec by name, in provider order (first wins)."""
    global _specs
    if _specs is None:
        found: dict[str, ProtocolSpec] = {}
        for name in _provider_modules():
            spec = _spec_of(importlib.import_module(name))
            if spec is None:
                log.warning("servobus provider %s declares no ProtocolSpec SPEC: skipped", name)
                continue
            found.setdefault(spec.name, spec)
        _specs = found
    return _specs


def provided(attribute: str) -> dict[str, str]:
    """One table (``SCHEMES``, ``SIM``, ``DECODERS`` ...) merged over every protocol's spec,
    first wins."""
    table = _tables.get(attribute)
    if table is None:
        table = {}
        for spec in specs().values():
            for key, target in _FROM_SPEC[attribute](spec).items():
                table.setdefault(key.lower(), target)
        _tables[attribute] = table
    return table


def provided_list(attribute: str) -> list[str]:
    """The single value of every spec that has one (``CLI``: ``"module:COMMANDS"``), in
    provider order."""
    found = [getattr(spec, attribute.lower()) for spec in specs().values()]
    return [value for value in found if isinstance(value, str)]


def schemes() -> dict[str, str]:
    """Every known scheme -> its opener target (providers are imported once, lightly)."""
    return {**provided("SERIAL_SCHEMES"), **provided("SCHEMES"), **BUILTIN_SCHEMES, **_extra}


def own_schemes() -> list[str]:
    """servobus's own schemes (not the pyserial URLs a serial protocol also takes), sorted."""
    return sorted({*provided("SCHEMES"), *BUILTIN_SCHEMES, *_extra} - {""})


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


def link_kind(url: DriveUrl) -> str | None:
    """What carries ``url``'s frames (ProtocolSpec.link), ``"virtual"`` for the built-in
    virtual drives (no wiring, power or baud), None for a scheme no spec declares."""
    if url.scheme in BUILTIN_SCHEMES:
        return "virtual"
    for spec in specs().values():
        if url.scheme in spec.schemes or url.scheme in spec.serial_schemes:
            return spec.link
    return None


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


def runs_inline(url: DriveUrl) -> bool:
    """The protocol serving ``url`` lists its scheme in ``inline_schemes``: its axes need no
    event loop between calls (the sync facade may run them on the caller's thread)."""
    if url.transport:
        return False
    name = protocol_of(url)
    spec = specs().get(name) if name is not None else None
    return spec is not None and url.scheme in spec.inline_schemes


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
