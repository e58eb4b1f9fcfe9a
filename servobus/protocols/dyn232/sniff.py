"""DYN232M line decoding for people (``servobus decode``/``sniff``, the GUI's monitor).

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

from collections.abc import Iterator
from dataclasses import dataclass, field

from servobus.errors import ChecksumError, ProtocolError
from servobus.families.dmm import params as P
from servobus.families.dmm.registers import DriveConfig, DriveStatus
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.sniff import ByteDecoder, ErrorEvent, raw_column

REPLY, CODE, VALUE, AMBIGUOUS = "reply", "code", "value", "ambiguous"


@dataclass(frozen=True)
class PacketEvent:
    """One packet with its inferred direction (see the module docstring)."""

    raw: bytes
    packet: c.Packet
    from_drive: bool
    basis: str  # REPLY, CODE, VALUE or AMBIGUOUS (see module docstring)
    text: str
    alternative: str | None = None  # the other reading when basis is AMBIGUOUS

    is_error = False

    @property
    def ambiguous(self) -> bool:
        return self.basis == AMBIGUOUS

    def lines(self, prefix: str = "", width: int = 21) -> list[str]:
        """One line; an ambiguous packet gets a second line with the other reading."""
        lines = [f"{prefix}{raw_column(self.raw.hex(' '), width)}{self.text}"]
        if self.ambiguous:
            lines[0] += "   [direction ambiguous]"
            lines.append(f"{prefix}{'':<{width}}or {self.alternative}")
        return lines

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
        if packet.function == DmmFunction.SET_DRIVE_CONFIG:
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
    spec = c.HOST_SPECS[c.host_function(packet.function)]
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
        reply = c.reply_function(c.host_function(packet.function), packet.value)
        if reply is not None:
            self._pending = (packet.drive_id, reply)


DECODER = ByteDecoder("dyn232", "DYN232M", LineDecoder)  # SPEC.decoder
