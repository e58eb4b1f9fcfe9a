"""Decoded traffic for people: what ``servobus decode``/``sniff`` and the GUI's monitor show.

Protocol-free: the event types every protocol's decoder yields, the two decoder shapes
(a byte stream on a serial line; frames on a CAN bus) and the parsers of what a person
types. Each protocol's spec names its decoder (``ProtocolSpec.decoder``, "module:object");
:func:`decoders` finds them through the registry.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar, runtime_checkable

BYTES, CAN = "bytes", "can"  # the two media a decoder can read


@dataclass(frozen=True)
class ErrorEvent:
    """Bytes or a frame that are not a valid packet: shown, counted, never decoded."""

    kind: str  # "checksum", "framing" (a byte stream) or "frame" (a CAN frame)
    message: str
    raw: bytes = b""
    raw_text: str = ""  # how to show the raw item when not as hex bytes (CAN: ``02e#``)

    is_error = True

    @property
    def label(self) -> str:
        return {"checksum": "checksum error", "frame": "invalid frame"}.get(self.kind, "garbage")

    def as_dict(self) -> dict[str, object]:
        return {"error": self.kind, "message": self.message,
                "raw": self.raw_text or self.raw.hex(" ")}

    def lines(self, prefix: str = "", width: int = 21) -> list[str]:
        raw = self.raw_text or self.raw.hex(" ")
        return [f"{prefix}{raw_column(raw, width)}{self.label}: {self.message}"]


@dataclass(frozen=True)
class FrameEvent:
    """One decoded CAN frame (any CAN protocol)."""

    arbitration_id: int
    data: bytes
    text: str

    is_error = False

    @property
    def raw_text(self) -> str:
        """candump/cansend notation: ``0e3#1b``."""
        return f"{self.arbitration_id:03x}#{self.data.hex()}"

    def as_dict(self) -> dict[str, object]:
        return {"id": self.arbitration_id, "data": self.data.hex(" "), "text": self.text}

    def lines(self, prefix: str = "", width: int = 21) -> list[str]:
        return [f"{prefix}{raw_column(self.raw_text, width)}{self.text}"]


def raw_column(raw: str, width: int) -> str:
    """The raw bytes padded to ``width``, with at least one space before the text however
    long they are (``01 03 ... 84 0a id 1 read``, never ``84 0aid 1``)."""
    return f"{raw:<{width - 1}} "


@runtime_checkable
class Event(Protocol):
    is_error: bool

    def as_dict(self) -> dict[str, object]: ...
    def lines(self, prefix: str = "", width: int = 21) -> list[str]: ...


class StreamDecoder(Protocol):
    """Decodes a serial line's bytes in any chunking."""

    def iter_feed(self, data: bytes | bytearray) -> Iterator[Event]: ...
    def finish(self) -> list[Event]: ...


class Decoder(Protocol):
    """What a protocol's spec names as its ``decoder``."""

    name: str
    medium: str  # BYTES or CAN

    def stream(self) -> StreamDecoder:
        """A new decoder for a byte stream (medium BYTES)."""

    def frame(self, arbitration_id: int, data: bytes) -> Event:
        """One CAN frame (medium CAN)."""


S = TypeVar("S")


class ByteDecoder(Generic[S]):
    """The decoder of a protocol on a byte stream (serial line, TCP capture):
    ``make()`` gives a new stream decoder; CAN frames are not its medium."""

    medium = BYTES

    def __init__(self, name: str, label: str, make: Callable[[], S]) -> None:
        self.name, self._label, self._make = name, label, make

    def stream(self) -> S:
        return self._make()

    def frame(self, arbitration_id: int, data: bytes) -> Event:
        return ErrorEvent("frame", f"{self._label} has no CAN frames")


class CanDecoder:
    """The decoder of a protocol on CAN: ``frame(arbitration_id, data)`` decodes
    one frame; there is no byte stream to feed."""

    medium = CAN

    def __init__(self, name: str, label: str, frame: Callable[[int, bytes], Event]) -> None:
        self.name, self._label, self._frame = name, label, frame

    def stream(self) -> StreamDecoder:
        raise NotImplementedError(f"{self._label} is read frame by frame")

    def frame(self, arbitration_id: int, data: bytes) -> Event:
        return self._frame(arbitration_id, data)


def decoders() -> dict[str, Decoder]:
    """Every protocol's decoder by protocol name, in provider order."""
    from servobus.axis import registry

    return {name: registry.load(target) for name, target in registry.provided("DECODERS").items()}


def decoder_for(medium: str, name: str | None = None) -> Decoder:
    """The decoder ``name`` (it must read ``medium``), or the first one that reads it."""
    found = decoders()
    if name is not None:
        chosen = found.get(name)
        if chosen is None or chosen.medium != medium:
            fitting = [n for n, d in found.items() if d.medium == medium]
            raise ValueError(f"no {medium} decoder {name!r}; known: {', '.join(fitting)}")
        return chosen
    for decoder in found.values():
        if decoder.medium == medium:
            return decoder
    raise ValueError(f"no protocol decodes {medium}")


def decode_stream(decoder: Decoder, chunks: Iterable[bytes]) -> Iterator[Event]:
    """Decode a whole finite byte source (including the end-of-input report)."""
    stream = decoder.stream()
    for chunk in chunks:
        yield from stream.iter_feed(chunk)
    yield from stream.finish()


def parse_hex(tokens: Iterable[str]) -> bytes:
    """Bytes from hex text in any spacing: ``03 a3 ff``, ``03a3ff``, ``0x03,0xa3``, ``03:a3``.

    Raises ValueError naming the offending token.
    """
    out = bytearray()
    for token in tokens:
        for part in token.replace(",", " ").replace(":", " ").replace(";", " ").split():
            digits = part[2:] if part.lower().startswith("0x") else part
            if len(digits) == 1:
                digits = "0" + digits
            if len(digits) % 2:
                raise ValueError(f"odd number of hex digits in {part!r}")
            try:
                out.extend(bytes.fromhex(digits))
            except ValueError:
                raise ValueError(f"not hex: {part!r}") from None
    return bytes(out)


HEX_TEXT_BYTES = frozenset(b"0123456789abcdefABCDEFxX,:; \t\r\n")


def looks_like_hex_text(data: bytes) -> bool:
    """True for text such as ``03 a3 ff 88 ad``: only hex digits and separators (a raw
    capture of a binary protocol has bytes >= 0x80 or control bytes; hex text never has)."""
    return bool(data) and HEX_TEXT_BYTES.issuperset(data) and any(
        chr(b) in "0123456789abcdefABCDEF" for b in data)


def parse_can_frame(token: str) -> tuple[int, bytes]:
    """``ID#DATA`` as cansend writes it (``0e3#1b``, ``7#de.ad``); ValueError if malformed."""
    ident, sep, data = token.partition("#")
    if not sep:
        raise ValueError(f"CAN frame {token!r} must be ID#DATA (hex)")
    try:
        arbitration_id = int(ident, 16)
    except ValueError:
        raise ValueError(f"CAN identifier {ident!r} is not hex") from None
    if not 0 <= arbitration_id <= 0x7FF:
        raise ValueError(f"CAN identifier 0x{arbitration_id:x} is not an 11-bit identifier")
    return arbitration_id, parse_hex([data.replace(".", "")]) if data else b""
