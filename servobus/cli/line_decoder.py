"""Human-readable DYN232M line decoding for ``servobus decode`` and ``servobus sniff``.

Pure (no I/O): bytes in, :class:`LineEvent` out. Built on the codec's Framer and tables.

Direction inference. On a raw RS485 tap the direction of a packet is not on the wire, and
the host codes 0x10..0x1E overlap the drive's ``Is_*`` codes (e.g. 0x19 is Read_SpeedGain
from the host and Is_Status from a drive). The rules, first match wins:

1. ``reply``  - the packet has the ``Is_*`` code the last host read request expects, from the
   same id (or any id if the request went to broadcast 127): a drive reply.
2. ``code``   - the code has no ``Is_*`` meaning (0x00..0x0F, 0x1C, 0x1F), or the id is 64..127
   (drives answer with their own id 0..63): a host packet.
3. ``value``  - exactly one reading has a plausible value: host reads carry a dummy byte 0,
   host writes must be inside the range the manual gives, a drive's parameter reply is in the
   parameter's range, Is_DriveID is 0..63, status/config replies are 1 byte 0..127.
4. ``ambiguous`` - both readings fit; the host reading is printed first (drives only talk
   when asked, so an unrequested reply is only likely at the very start of a capture or after
   a lost request) and the drive reading is given as the alternative.

A packet classified as a host read becomes the pending request for rule 1; any other packet
clears it (the drive answers at once, so a reply never comes after an unrelated packet).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

from servobus.codec import dyn232 as c
from servobus.codec import dyncan
from servobus.drive import params as P
from servobus.drive.registers import DriveConfig, DriveStatus
from servobus.errors import ChecksumError, ProtocolError

REPLY, CODE, VALUE, AMBIGUOUS = "reply", "code", "value", "ambiguous"


@dataclass(frozen=True)
class PacketEvent:
    raw: bytes
    packet: c.Packet
    from_drive: bool
    basis: str  # REPLY, CODE, VALUE or AMBIGUOUS (see module docstring)
    text: str
    alternative: str | None = None  # the other reading when basis is AMBIGUOUS

    @property
    def ambiguous(self) -> bool:
        return self.basis == AMBIGUOUS

    def as_dict(self) -> dict[str, object]:
        p = self.packet
        d: dict[str, object] = {
            "raw": self.raw.hex(" "),
            "direction": "drive->host" if self.from_drive else "host->drive",
            "drive_id": p.drive_id,
            "code": p.function,
            "function": c.function_name(p.function, self.from_drive),
            "value": p.reply_value() if self.from_drive else p.value,
            "basis": self.basis,
            "text": self.text,
        }
        if self.alternative is not None:
            d["alternative"] = self.alternative
        return d


@dataclass(frozen=True)
class ErrorEvent:
    kind: str  # "checksum", "framing" (DYN232M bytes) or "frame" (a CAN frame)
    message: str
    raw: bytes = b""
    raw_text: str = ""  # how to show the raw item when not as hex bytes (CAN: ``02e#``)

    @property
    def label(self) -> str:
        return {"checksum": "checksum error", "frame": "invalid frame"}.get(self.kind, "garbage")

    def as_dict(self) -> dict[str, object]:
        return {"error": self.kind, "message": self.message,
                "raw": self.raw_text or self.raw.hex(" ")}


LineEvent = PacketEvent | ErrorEvent


def _status_text(value: int) -> str:
    s = DriveStatus.from_byte(value)
    parts = ["on position" if s.on_position else "off position"]
    if s.servo_free:
        parts.append("servo free")
    if s.motion_busy:
        parts.append("motion busy")
    if s.alarm:
        parts.append(f"ALARM {int(s.alarm)} {s.alarm.name.lower()}")
    if s.jp3_pin2:
        parts.append("JP3 pin 2 high")
    return ", ".join(parts)


def _config_text(value: int) -> str:
    cfg = DriveConfig.from_byte(value)
    parts = [f"command {cfg.command_mode.name.lower()}", f"{cfg.servo_mode.name.lower()} mode",
             "absolute" if cfg.absolute else "relative"]
    if cfg.free:
        parts.append("servo free")
    return ", ".join(parts)


def _detail(packet: c.Packet, from_drive: bool) -> str:
    """Extra decoding of register values, appended to the codec's describe()."""
    byte = packet.unsigned & 0x7F
    if not from_drive:
        if packet.function == c.HostFunction.SET_DRIVE_CONFIG:
            return f" (0x{byte:02x}: {_config_text(byte)})"
        return ""
    if packet.function == c.DriveFunction.IS_STATUS:
        return f" (0x{byte:02x}: {_status_text(byte)})"
    if packet.function == c.DriveFunction.IS_CONFIG:
        return f" (0x{byte:02x}: {_config_text(byte)})"
    if packet.function == c.DriveFunction.IS_ABS_POS32:
        return " counts"
    if packet.function == c.DriveFunction.IS_SPEED:
        return " rpm"
    return ""


def text_of(packet: c.Packet, from_drive: bool) -> str:
    return c.describe(packet, from_drive) + _detail(packet, from_drive)


def _host_plausible(packet: c.Packet) -> bool:
    spec = c.HOST_SPECS[c.HostFunction(packet.function)]
    if spec.kind is c.Kind.READ and spec.minimum == spec.maximum == 0:
        return packet.value == 0  # dummy byte
    return spec.minimum <= packet.value <= spec.maximum


def _drive_plausible(packet: c.Packet) -> bool:
    fn = c.DriveFunction(packet.function)
    spec = c.DRIVE_SPECS[fn]
    value = packet.reply_value()
    if spec.param is not None:
        return P.spec(spec.param).valid(value)
    if fn is c.DriveFunction.IS_DRIVE_ID:
        return 0 <= value <= c.MAX_DRIVE_ID
    if spec.unsigned:  # status / config: one 7-bit register byte
        return len(packet.data) == 1
    return True


def _is_drive_code(function: int) -> bool:
    try:
        c.DriveFunction(function)
    except ValueError:
        return False
    return True


@dataclass
class LineDecoder:
    """Feed raw line bytes in any chunking; get PacketEvent/ErrorEvent in line order."""

    framer: c.Framer = field(default_factory=c.Framer)
    _pending: tuple[int, c.DriveFunction] | None = None  # (request id, expected reply code)

    def feed(self, data: bytes | bytearray) -> list[LineEvent]:
        return list(self.iter_feed(data))

    def iter_feed(self, data: bytes | bytearray) -> Iterator[LineEvent]:
        for item in self.framer.iter_feed(data):
            if isinstance(item, ProtocolError):
                self._pending = None
                raw = item.raw if isinstance(item, ChecksumError) else b""
                kind = "checksum" if isinstance(item, ChecksumError) else "framing"
                yield ErrorEvent(kind, str(item), raw)
            else:
                yield self.classify(item)

    def finish(self) -> list[LineEvent]:
        """End of input: report a packet cut short or stray bytes still held by the framer."""
        # A start byte (MSB 0) makes the framer flush what it holds; the byte itself is
        # never reported because the framer is reset right after.
        events = [e for e in self.iter_feed(b"\x00")]
        self.framer.reset()
        return events

    def classify(self, packet: c.Packet) -> PacketEvent:
        raw = c.encode_packet(packet)
        pending, self._pending = self._pending, None
        if pending is not None and packet.function == pending[1] and (
            pending[0] in (packet.drive_id, c.BROADCAST_ID)
        ):
            return PacketEvent(raw, packet, True, REPLY, text_of(packet, True))
        if not _is_drive_code(packet.function) or packet.drive_id > c.MAX_DRIVE_ID:
            event = PacketEvent(raw, packet, False, CODE, text_of(packet, False))
        else:
            host_ok, drive_ok = _host_plausible(packet), _drive_plausible(packet)
            if host_ok != drive_ok:
                from_drive = drive_ok
                event = PacketEvent(raw, packet, from_drive, VALUE, text_of(packet, from_drive))
            else:
                event = PacketEvent(raw, packet, False, AMBIGUOUS, text_of(packet, False),
                                    alternative=text_of(packet, True))
        if not event.from_drive:
            self._expect_reply(packet)
        return event

    def _expect_reply(self, packet: c.Packet) -> None:
        reply = c.reply_function(c.HostFunction(packet.function), packet.value)
        if reply is not None:
            self._pending = (packet.drive_id, reply)


def decode_stream(chunks: Iterable[bytes]) -> Iterator[LineEvent]:
    """Decode a whole finite byte source (including the end-of-input report)."""
    decoder = LineDecoder()
    for chunk in chunks:
        yield from decoder.iter_feed(chunk)
    yield from decoder.finish()


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
    """True for text such as ``03 a3 ff 88 ad``: only hex digits and separators.

    A raw DYN232M capture cannot look like this: every packet's data and checksum bytes
    have their MSB set (DYN2 manual 7.2), and hex text is 7-bit ASCII.
    """
    return bool(data) and HEX_TEXT_BYTES.issuperset(data) and any(
        chr(b) in "0123456789abcdefABCDEF" for b in data)


# ------------------------------------------------------------------ DYN CAN frames
@dataclass(frozen=True)
class CanEvent:
    """One DYN CAN frame; direction from the frame's shape (dyncan.describe: replies reuse the
    request's identifier, so the data length against the function table tells them apart)."""

    arbitration_id: int
    data: bytes
    text: str

    @property
    def raw_text(self) -> str:
        """candump/cansend notation: ``0e3#1b``."""
        return f"{self.arbitration_id:03x}#{self.data.hex()}"

    def as_dict(self) -> dict[str, object]:
        return {"id": self.arbitration_id, "data": self.data.hex(" "), "text": self.text}


def can_length_error(frame: dyncan.Frame) -> str | None:
    """Why the frame's data length fits neither the request nor the reply of its function.

    The function table gives both lengths (DYN CAN specification 1.2A, section 5); a frame
    that fits neither is reported, never decoded with made-up data (an empty 0x0E frame is not
    General_Read 0). DMM-internal functions (0x0F, 0x1B) are shown as they are.
    """
    spec = frame.spec
    shapes: list[tuple[str, tuple[int, int]]] = []
    if spec.kind is not dyncan.Kind.INTERNAL:  # internal functions are never host requests
        shapes.append(("request", spec.sent))
    if spec.reply is not None:
        shapes.append(("reply", spec.returned))
    n = len(frame.data)
    if not shapes or any(lo <= n <= hi for _, (lo, hi) in shapes):
        return None
    allowed = " or ".join(f"{lo if lo == hi else f'{lo}..{hi}'} ({what})"
                          for what, (lo, hi) in shapes)
    return f"{spec.function.name} takes {allowed} data byte(s); this frame has {n}"


def can_event(arbitration_id: int, data: bytes) -> CanEvent | ErrorEvent:
    raw_text = f"{arbitration_id:03x}#{bytes(data).hex()}"
    try:
        frame = dyncan.decode(arbitration_id, data)
    except ProtocolError as exc:
        return ErrorEvent("frame", str(exc), bytes(data), raw_text)
    problem = can_length_error(frame)
    if problem is not None:
        return ErrorEvent("frame", problem, bytes(data), raw_text)
    return CanEvent(arbitration_id, bytes(data), dyncan.describe(frame))


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
