"""Drive URLs: one string names the protocol, the transport and the target (docs/axis.md).

Forms (``scheme[+transport]:target[?options]``)::

    dyn232:///dev/ttyUSB0   dyn232:COM3   dyn232+socket://127.0.0.1:4001
    /dev/ttyUSB0   COM3   socket://host:port   loop://     (bare serial: DYN232M)
    dyncan+pcan://PCAN_USBBUS1   dyncan+socketcand://127.0.0.1:29536/can0
    dyncan+virtual://bus0?bitrate=1000000
    sim://dyn232?ids=1,2,3&fast=1        (in-process virtual drives of any protocol)

Parsing is pure and knows no protocol: which schemes exist is the registry's business
(:mod:`servobus.axis.registry`). A bare serial port or pyserial URL takes the registry's
``BARE_SERIAL_PROTOCOL`` as its protocol there, not here.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from urllib.parse import parse_qsl

from servobus.axis.options import connect_options
from servobus.errors import InvalidValue

#: RFC 3986 scheme syntax; one letter is a Windows drive (``C:``), not a scheme.
_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]+):(.*)$", re.DOTALL)
_COM_PORT = re.compile(r"^COM\d+$", re.IGNORECASE)


@dataclass(frozen=True)
class DriveUrl:
    """A parsed drive URL.

    ``scheme`` is the protocol part (``dyn232``, ``dyncan``, ``sim``; ``""`` for a bare port
    or a plain pyserial URL), ``transport`` what follows ``+`` (``socket``, ``pcan``; ``""``),
    ``target`` the rest without ``//`` and the query: ``h:p`` for ``dyn232+socket://h:p``,
    ``CH`` for ``dyncan+pcan://CH``, ``/dev/ttyS0`` for ``dyn232:///dev/ttyS0``, ``COM3``
    for ``dyn232:COM3``, ``dyn232`` for ``sim://dyn232``. :attr:`inner` rebuilds the
    transport's own URL (``socket://h:p``) for protocols that hand it to pyserial.
    """

    raw: str
    scheme: str
    transport: str
    target: str
    options: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def inner(self) -> str:
        """The URL the transport understands: ``socket://h:p`` for ``x+socket://h:p``."""
        return f"{self.transport}://{self.target}" if self.transport else self.target

    @property
    def link_key(self) -> str:
        """The same string for two spellings of one link: ``socket://h:4001`` and
        ``socket://h:4001/``, query options in any order (scheme case is already folded).
        A machine file keys its links and refuses two axes on one drive by it."""
        query = "&".join(f"{k}={v}" for k, v in sorted(self.options.items()))
        scheme = f"{self.scheme}+{self.transport}" if self.transport else self.scheme
        return f"{scheme}://{self.target.rstrip('/') or self.target}?{query}"

    def option(self, name: str, default: str | None = None) -> str | None:
        return self.options.get(name, default)

    def int_option(self, name: str, default: int | None = None) -> int | None:
        text = self.options.get(name)
        if text is None:
            return default
        try:
            return int(text, 0)
        except ValueError:
            raise InvalidValue(
                f"?{name}={text!r} in {self.raw!r} is not an integer") from None

    def float_option(self, name: str, default: float | None = None) -> float | None:
        text = self.options.get(name)
        if text is None:
            return default
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise InvalidValue(f"?{name}={text!r} in {self.raw!r} is not a number")
        return value


def _split_query(text: str) -> tuple[str, dict[str, str]]:
    if "?" not in text:
        return text, {}
    body, query = text.split("?", 1)
    try:
        pairs = parse_qsl(query, keep_blank_values=True, strict_parsing=True)
    except ValueError:
        raise InvalidValue(f"malformed query {query!r}: use ?name=value&name=value") from None
    options: dict[str, str] = {}
    for key, value in pairs:
        if key in options:
            raise InvalidValue(f"option {key!r} given twice in ?{query}")
        options[key] = value
    return body, options


def parse_url(url: str) -> DriveUrl:
    """Split ``url`` into scheme, transport, target and options (no protocol knowledge)."""
    if not isinstance(url, str) or not url.strip():
        raise InvalidValue(f"a drive URL must be a non-empty string, got {url!r}")
    url = url.strip()
    match = _SCHEME.match(url)
    if match is None or _COM_PORT.match(url):
        body, options = _split_query(url)  # bare port: /dev/ttyUSB0, COM3, ./pty
        return DriveUrl(url, "", "", body, MappingProxyType(options))
    scheme, rest = match.group(1).lower(), match.group(2)
    base, _, transport = scheme.partition("+")
    body, options = _split_query(rest)
    target = body[2:] if body.startswith("//") else body
    return DriveUrl(url, base, transport, target, MappingProxyType(options))



#: Query options every protocol understands, with their types (docs/axis.md has the table).
OptionTypes = dict[str, type]


def merge_options(url: DriveUrl, keywords: dict[str, object],
                  types: OptionTypes) -> dict[str, object]:
    """Keyword options override URL query options; both are checked against ``types``.

    Unknown names raise ArgumentRangeError listing the known ones, and every value is checked
    (:func:`servobus.axis.options.connect_options`), before anything is opened.
    """
    known = ", ".join(sorted(types)) or "none"
    merged: dict[str, object] = {}
    for name in url.options:
        kind = types.get(name)
        if kind is None:
            raise InvalidValue(f"unknown option ?{name}= in {url.raw!r}; known: {known}")
        if kind is int:
            merged[name] = url.int_option(name)
        elif kind is float:
            merged[name] = url.float_option(name)
        elif kind is bool:
            merged[name] = url.options[name].lower() in ("1", "true", "yes", "on")
        else:
            merged[name] = url.options[name]
    for name, value in keywords.items():
        if name not in types:
            raise InvalidValue(f"unknown connect option {name!r}; known: {known}")
        merged[name] = value
    connect_options(merged, types)
    return merged


def can_spec(url: DriveUrl) -> tuple[str, dict[str, str]]:
    """``INTERFACE:CHANNEL`` for python-can, and the socketcand bus name if the URL gives one.

    ``<scheme>+<interface>://<channel>``; for socketcand the channel is ``host:port[/can0]``
    (the CAN protocols' URLs: DYN CAN and EasyCan).
    """
    if not url.transport:
        s = url.scheme
        raise InvalidValue(
            f"{url.raw!r} names no CAN interface: use {s}+<interface>://<channel>, "
            f"e.g. {s}+pcan://PCAN_USBBUS1 or {s}+socketcand://127.0.0.1:29536/can0")
    channel = url.target
    if url.transport == "socketcand" and "/" in channel:
        address, _, bus = channel.partition("/")
        return f"socketcand:{address}", ({"channel": bus} if bus else {})
    return f"{url.transport}:{channel}", {}
