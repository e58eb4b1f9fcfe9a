"""DYN232M serial packets (DYN2 / DC2 / DYN4 manual section 7). Pure: bytes <-> Packet.

Packet on the wire (the manual's Bn .. B0, sent Bn first)::

    Bn      0 id[6:0]                      start byte (MSB 0)
    Bn-1    1 len[1:0] fn[4:0]             len = packet length - 4 = data bytes - 1
    ...     1 d[6:0]                       1..4 data bytes, 7-bit groups, MS group first
    B0      1 sum[6:0]                     sum of all previous bytes, mod 128

Data is two's complement over 7 x n bits (28 bits for 4 bytes). Decisions (docs/dyn232.md) kept
here: encode with the fewest data bytes that hold the value; decode any length 1..4; the
1-byte replies of register/parameter reads are 7-bit unsigned.

Erratum (docs/errata.md, DYN2): the 1,400 rpm example in 7.4.2 shows the data bytes
as 0x85 0xF8, splitting 0x578 by hex digit; in 7-bit groups 1,400 is 0x8A 0xF8 (0x85 0xF8
would be 760). The worked examples 1-6 and DMM's sample code agree with the 7-bit rule.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from enum import IntEnum

from servobus.errors import ArgumentRangeError, ChecksumError, FramingError, ProtocolError
from servobus.families.dmm.vocabulary import (  # re-exported: the shared DMM vocabulary
    CONST_SPEED_LIMIT_RPM as CONST_SPEED_LIMIT_RPM,
)
from servobus.families.dmm.vocabulary import MAX_DRIVE_ID as MAX_DRIVE_ID  # 64..126 reserved
from servobus.families.dmm.vocabulary import VALUE_MAX as VALUE_MAX
from servobus.families.dmm.vocabulary import VALUE_MIN as VALUE_MIN
from servobus.families.dmm.vocabulary import WAVE_AMPLITUDE_MAX as WAVE_AMPLITUDE_MAX
from servobus.families.dmm.vocabulary import WAVE_FREQUENCY_MAX_HZ as WAVE_FREQUENCY_MAX_HZ
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.families.dmm.vocabulary import GeneralReadSelector as GeneralReadSelector
from servobus.families.dmm.vocabulary import Kind as Kind

BROADCAST_ID = 127
FACTORY_ID = 0
MIN_PACKET = 4
MAX_PACKET = 7
BAUD = 38_400
BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop


class HostFunction(IntEnum):
    """DYN232M's own host function codes (7.2.4), 0x10-0x1F: the parameter sets and reads.
    0x00-0x0F are the shared DMM codes, :class:`~servobus.families.dmm.vocabulary.DmmFunction`
    (one enum for both DMM protocols)."""

    SET_MAIN_GAIN = 0x10
    SET_SPEED_GAIN = 0x11
    SET_INT_GAIN = 0x12
    SET_TRQ_CONS = 0x13
    SET_HIGH_SPEED = 0x14
    SET_HIGH_ACCEL = 0x15
    SET_POS_ON_RANGE = 0x16
    SET_GEAR_NUMBER = 0x17
    READ_MAIN_GAIN = 0x18
    READ_SPEED_GAIN = 0x19
    READ_INT_GAIN = 0x1A
    READ_TRQ_CONS = 0x1B
    READ_HIGH_SPEED = 0x1C
    READ_HIGH_ACCEL = 0x1D
    READ_POS_ON_RANGE = 0x1E
    READ_GEAR_NUMBER = 0x1F


#: A function code the host sends: a shared DMM code or one of DYN232M's own.
HostCode = DmmFunction | HostFunction
#: Every host function code, 0x00..0x1F in order.
HOST_FUNCTIONS: tuple[HostCode, ...] = (*DmmFunction, *HostFunction)


def host_function(code: int) -> HostCode:
    """The host function of a 5-bit code (ValueError for a code no enum has)."""
    return DmmFunction(code) if code < HostFunction.SET_MAIN_GAIN else HostFunction(code)


class DriveFunction(IntEnum):
    """Function codes sent by the drive (the ``Is_*`` replies)."""

    IS_MAIN_GAIN = 0x10
    IS_SPEED_GAIN = 0x11
    IS_INT_GAIN = 0x12
    IS_TRQ_CONS = 0x13
    IS_HIGH_SPEED = 0x14
    IS_HIGH_ACCEL = 0x15
    IS_DRIVE_ID = 0x16
    IS_POS_ON_RANGE = 0x17
    IS_GEAR_NUMBER = 0x18
    IS_STATUS = 0x19
    IS_CONFIG = 0x1A
    IS_ABS_POS32 = 0x1B
    IS_SPEED = 0x1D  # DMM's library: General_Read selector 0x1D, speed in rpm
    IS_TRQ_CURRENT = 0x1E




@dataclass(frozen=True)
class HostSpec:
    function: HostCode
    kind: Kind
    minimum: int  # allowed argument range, checked by the client before sending
    maximum: int
    reply: DriveFunction | None = None
    param: str | None = None  # drive.params name for parameter set/read functions
    doc: str = ""


@dataclass(frozen=True)
class DriveSpec:
    function: DriveFunction
    unsigned: bool  # 1-byte 7-bit unsigned (register and parameter values)
    param: str | None = None


_M, _H, _K = DmmFunction, HostFunction, Kind
_FULL = (VALUE_MIN, VALUE_MAX)
_DUMMY = (0, 0)

HOST_SPECS: dict[HostCode, HostSpec] = {
    s.function: s
    for s in (
        HostSpec(_M.SET_ORIGIN, _K.ACTION, *_DUMMY, doc="current position becomes zero"),
        HostSpec(_M.GO_ABSOLUTE_POS, _K.MOTION, *_FULL, doc="S-curve move to position"),
        HostSpec(_M.MAKE_LINEAR_LINE, _K.MOTION, *_FULL, doc="3-axis line (broadcast)"),
        HostSpec(_M.GO_RELATIVE_POS, _K.MOTION, *_FULL, doc="S-curve move by distance"),
        HostSpec(_M.MAKE_CIRCULAR_ARC, _K.MOTION, *_FULL, doc="3-axis arc (broadcast)"),
        HostSpec(_M.ASSIGN_DRIVE_ID, _K.SETTING, 0, MAX_DRIVE_ID, doc="new drive id"),
        HostSpec(_M.READ_DRIVE_ID, _K.READ, *_DUMMY, reply=DriveFunction.IS_DRIVE_ID),
        HostSpec(_M.SET_DRIVE_CONFIG, _K.SETTING, 0, 0x7F, doc="config byte (7.3)"),
        HostSpec(_M.READ_DRIVE_CONFIG, _K.READ, *_DUMMY, reply=DriveFunction.IS_CONFIG),
        HostSpec(_M.READ_DRIVE_STATUS, _K.READ, *_DUMMY, reply=DriveFunction.IS_STATUS),
        HostSpec(_M.TURN_CONST_SPEED, _K.MOTION, -CONST_SPEED_LIMIT_RPM, CONST_SPEED_LIMIT_RPM,
                 doc="rpm, positive CW"),
        HostSpec(_M.SQUARE_WAVE, _K.MOTION, 0, WAVE_AMPLITUDE_MAX, doc="4096 = 180 deg"),
        HostSpec(_M.SIN_WAVE, _K.MOTION, 0, WAVE_AMPLITUDE_MAX, doc="4096 = 180 deg"),
        HostSpec(_M.SS_FREQUENCY, _K.MOTION, 0, WAVE_FREQUENCY_MAX_HZ, doc="Hz, 0 stops"),
        HostSpec(_M.GENERAL_READ, _K.READ, 0x1B, 0x21, doc="selector, see GeneralReadSelector"),
        HostSpec(_M.FOR_MOTOR_DEFINE, _K.INTERNAL, *_DUMMY, doc="DMM internal; never sent"),
        HostSpec(_H.SET_MAIN_GAIN, _K.SETTING, 1, 127, param="main_gain"),
        HostSpec(_H.SET_SPEED_GAIN, _K.SETTING, 1, 127, param="speed_gain"),
        HostSpec(_H.SET_INT_GAIN, _K.SETTING, 1, 127, param="int_gain"),
        HostSpec(_H.SET_TRQ_CONS, _K.SETTING, 1, 127, param="trq_cons"),
        HostSpec(_H.SET_HIGH_SPEED, _K.SETTING, 1, 127, param="max_speed"),
        HostSpec(_H.SET_HIGH_ACCEL, _K.SETTING, 1, 127, param="max_accel"),
        HostSpec(_H.SET_POS_ON_RANGE, _K.SETTING, 1, 127, param="on_range"),
        HostSpec(_H.SET_GEAR_NUMBER, _K.SETTING, 500, 16_384, param="gear_num"),
        HostSpec(_H.READ_MAIN_GAIN, _K.READ, *_DUMMY, DriveFunction.IS_MAIN_GAIN, "main_gain"),
        HostSpec(_H.READ_SPEED_GAIN, _K.READ, *_DUMMY, DriveFunction.IS_SPEED_GAIN, "speed_gain"),
        HostSpec(_H.READ_INT_GAIN, _K.READ, *_DUMMY, DriveFunction.IS_INT_GAIN, "int_gain"),
        HostSpec(_H.READ_TRQ_CONS, _K.READ, *_DUMMY, DriveFunction.IS_TRQ_CONS, "trq_cons"),
        HostSpec(_H.READ_HIGH_SPEED, _K.READ, *_DUMMY, DriveFunction.IS_HIGH_SPEED, "max_speed"),
        HostSpec(_H.READ_HIGH_ACCEL, _K.READ, *_DUMMY, DriveFunction.IS_HIGH_ACCEL, "max_accel"),
        HostSpec(_H.READ_POS_ON_RANGE, _K.READ, *_DUMMY, DriveFunction.IS_POS_ON_RANGE,
                 "on_range"),
        HostSpec(_H.READ_GEAR_NUMBER, _K.READ, *_DUMMY, DriveFunction.IS_GEAR_NUMBER, "gear_num"),
    )
}

_D = DriveFunction
DRIVE_SPECS: dict[DriveFunction, DriveSpec] = {
    s.function: s
    for s in (
        DriveSpec(_D.IS_MAIN_GAIN, True, "main_gain"),
        DriveSpec(_D.IS_SPEED_GAIN, True, "speed_gain"),
        DriveSpec(_D.IS_INT_GAIN, True, "int_gain"),
        DriveSpec(_D.IS_TRQ_CONS, True, "trq_cons"),
        DriveSpec(_D.IS_HIGH_SPEED, True, "max_speed"),
        DriveSpec(_D.IS_HIGH_ACCEL, True, "max_accel"),
        DriveSpec(_D.IS_DRIVE_ID, True),
        DriveSpec(_D.IS_POS_ON_RANGE, True, "on_range"),
        DriveSpec(_D.IS_GEAR_NUMBER, False, "gear_num"),
        DriveSpec(_D.IS_STATUS, True),
        DriveSpec(_D.IS_CONFIG, True),
        DriveSpec(_D.IS_ABS_POS32, False),
        DriveSpec(_D.IS_SPEED, False),
        DriveSpec(_D.IS_TRQ_CURRENT, False),
    )
}

#: Reply function codes (plain ints) whose 1-byte data reads as 7-bit unsigned.
_UNSIGNED_REPLIES = frozenset(int(f) for f, spec in DRIVE_SPECS.items() if spec.unsigned)

#: General_Read selectors that are answered, and with which function.
GENERAL_READ_REPLIES: dict[GeneralReadSelector, DriveFunction] = {
    GeneralReadSelector.POSITION: DriveFunction.IS_ABS_POS32,
    GeneralReadSelector.SPEED: DriveFunction.IS_SPEED,
    GeneralReadSelector.TORQUE: DriveFunction.IS_TRQ_CURRENT,
}

#: Parameter name -> (set function, read function), derived from HOST_SPECS.
PARAM_FUNCTIONS: dict[str, tuple[HostCode, HostCode]] = {
    name: (
        next(s.function for s in HOST_SPECS.values() if s.param == name and s.kind is Kind.SETTING),
        next(s.function for s in HOST_SPECS.values() if s.param == name and s.kind is Kind.READ),
    )
    for name in dict.fromkeys(s.param for s in HOST_SPECS.values() if s.param)
}


def reply_function(function: HostCode, value: int = 0) -> DriveFunction | None:
    """The Is_* function that answers a host packet, or None when the drive stays silent."""
    if function is DmmFunction.GENERAL_READ:
        try:
            return GENERAL_READ_REPLIES.get(GeneralReadSelector(value))
        except ValueError:
            return None
    return HOST_SPECS[function].reply


@dataclass(frozen=True)
class Packet:
    """One decoded packet. ``data`` holds the 7-bit groups (MSB cleared), MS group first."""

    drive_id: int
    function: int  # 0..31; a HostCode or DriveFunction depending on direction
    data: bytes

    @property
    def value(self) -> int:
        """Data as signed two's complement over 7 x len(data) bits."""
        raw = self.unsigned
        bits = 7 * len(self.data)
        return raw - (1 << bits) if raw & (1 << (bits - 1)) else raw

    @property
    def unsigned(self) -> int:
        raw = 0
        for b in self.data:
            raw = (raw << 7) | (b & 0x7F)
        return raw

    @property
    def length(self) -> int:
        return len(self.data) + 3

    def reply_value(self) -> int:
        """Value of a drive reply: 7-bit unsigned for 1-byte register/parameter replies."""
        return reply_value_of(self.function, self.data) if self.data else self.value

    def describe(self, from_drive: bool) -> str:
        """One line for traces, ``decode`` and ``sniff`` (see :func:`describe`)."""
        return describe(self, from_drive)


def reply_value_of(function: int, data: bytes | bytearray) -> int:
    """:meth:`Packet.reply_value` of a reply's 1..4 data groups (their MSBs are ignored)."""
    raw = 0
    for b in data:
        raw = (raw << 7) | (b & 0x7F)
    if len(data) == 1 and function in _UNSIGNED_REPLIES:
        return raw
    sign = 1 << (7 * len(data) - 1)
    return raw - (sign << 1) if raw & sign else raw


def data_length(value: int) -> int:
    """Fewest 7-bit groups (1..4) that hold ``value`` as two's complement."""
    for n in range(1, 5):
        lim = 1 << (7 * n - 1)
        if -lim <= value < lim:
            return n
    raise ArgumentRangeError(
        f"value {value} is outside the 28-bit packet range {VALUE_MIN}..{VALUE_MAX}"
    )


def checksum(body: bytes | bytearray) -> int:
    """B0 = 0x80 + (sum of Bn..B1) mod 128 (7.2.6)."""
    return 0x80 | (sum(body) & 0x7F)


def encode(drive_id: int, function: int, value: int = 0, *, unsigned: bool = False) -> bytes:
    """Build one packet. ``unsigned`` sends 0..127 in one byte (drive register replies)."""
    if not 0 <= drive_id <= 0x7F:
        raise ArgumentRangeError(f"drive id {drive_id} is outside 0..127")
    if not 0 <= function <= 0x1F:
        raise ArgumentRangeError(f"function code {function} is outside 0x00..0x1F")
    if unsigned and 0 <= value <= 0x7F:
        n, raw = 1, value
    else:
        n = data_length(value)
        raw = value & ((1 << (7 * n)) - 1)
    body = bytearray((drive_id, 0x80 | ((n - 1) << 5) | function))
    for shift in range(7 * (n - 1), -1, -7):
        body.append(0x80 | ((raw >> shift) & 0x7F))
    body.append(checksum(body))
    return bytes(body)


def encode_packet(packet: Packet) -> bytes:
    """Encode a Packet exactly as it is (its data length is kept, e.g. padded encodings)."""
    body = bytearray((packet.drive_id & 0x7F, 0x80 | ((len(packet.data) - 1) << 5)
                      | (packet.function & 0x1F)))
    body.extend(0x80 | (b & 0x7F) for b in packet.data)
    body.append(checksum(body))
    return bytes(body)


def encode_reply(drive_id: int, function: DriveFunction, value: int) -> bytes:
    """Encode a drive reply, honouring the unsigned 1-byte register/parameter rule."""
    return encode(drive_id, function, value, unsigned=DRIVE_SPECS[function].unsigned)


def decode(raw: bytes | bytearray) -> Packet:
    """Decode exactly one packet; raise FramingError or ChecksumError."""
    if type(raw) is not bytes:
        raw = bytes(raw)
    if not MIN_PACKET <= len(raw) <= MAX_PACKET:
        raise FramingError(f"packet length {len(raw)} is outside 4..7: {raw.hex(' ')}")
    if raw[0] & 0x80:
        raise FramingError(f"first byte 0x{raw[0]:02x} is not a start byte")
    if min(raw[1:]) < 0x80:
        raise FramingError(f"start byte inside packet: {raw.hex(' ')}")
    declared = 4 + ((raw[1] >> 5) & 0x03)
    if declared != len(raw):
        raise FramingError(f"length field says {declared} bytes, got {len(raw)}")
    if (sum(raw[:-1]) ^ raw[-1]) & 0x7F:
        raise ChecksumError(
            f"checksum 0x{raw[-1]:02x} != 0x{checksum(raw[:-1]):02x} in {raw.hex(' ')}", raw
        )
    return Packet(raw[0], raw[1] & 0x1F, raw[2:-1].translate(_LOW7))


_LOW7 = bytes(b & 0x7F for b in range(256))  # bytes.translate table: clear the MSB


FramerEvent = Packet | ProtocolError


class Framer:
    """Incremental stream framer: feed bytes in any chunking, get packets or errors out.

    A byte with MSB 0 always starts a new packet (7.2.2), so after garbage or a lost byte
    the framer resynchronises on the next start byte. A packet cut short by a new start
    byte yields FramingError; a bad checksum yields ChecksumError; stray bytes with MSB 1
    outside a packet are counted in ``discarded`` and reported once per run as FramingError.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._expected = 0
        self._stray = 0
        self.discarded = 0

    def feed(self, data: bytes | bytearray | Iterable[int]) -> list[FramerEvent]:
        if self.whole_packet(data):
            assert isinstance(data, bytes | bytearray)
            try:
                return [decode(data)]
            except ProtocolError as exc:
                return [exc]
        return list(self.iter_feed(data))

    def whole_packet(self, data: object) -> bool:
        """Fast path: ``data`` is exactly one packet and nothing is pending (the usual case:
        transports deliver a short reply in one chunk). Same events as the byte loop."""
        return (isinstance(data, bytes | bytearray) and not self._buf and not self._stray
                and MIN_PACKET <= len(data) <= MAX_PACKET and data[0] < 0x80
                and len(data) == 4 + ((data[1] >> 5) & 0x03) and min(data[1:]) >= 0x80)

    def whole_reply(self, data: bytes | bytearray) -> tuple[int, int, int] | None:
        """(drive id, function, reply value) when ``data`` is exactly one packet with a
        good checksum and the framer holds nothing; else None and nothing changes (then
        :meth:`feed` the data). The cheapest way to take a reply that came in one chunk."""
        if not self.whole_packet(data) or (sum(data[:-1]) ^ data[-1]) & 0x7F:
            return None
        return data[0], data[1] & 0x1F, reply_value_of(data[1] & 0x1F, data[2:-1])

    def iter_feed(self, data: bytes | bytearray | Iterable[int]) -> Iterator[FramerEvent]:
        if self.whole_packet(data):
            assert isinstance(data, bytes | bytearray)
            try:
                packet = decode(data)
            except ProtocolError as exc:
                yield exc
                return
            yield packet
            return
        buf = self._buf
        for b in data:
            if not b & 0x80:
                if buf:
                    self.discarded += len(buf)
                    yield FramingError(f"truncated packet {bytes(buf).hex(' ')}")
                yield from self._flush_stray()
                buf.clear()
                buf.append(b)
                self._expected = 0
                continue
            if not buf:
                self._stray += 1
                self.discarded += 1
                continue
            buf.append(b)
            if len(buf) == 2:
                self._expected = 4 + ((b >> 5) & 0x03)
            elif len(buf) == self._expected:
                raw = bytes(buf)
                buf.clear()
                try:
                    yield decode(raw)
                except ProtocolError as exc:
                    yield exc

    def _flush_stray(self) -> Iterator[FramerEvent]:
        if self._stray:
            n, self._stray = self._stray, 0
            yield FramingError(f"{n} stray byte(s) outside a packet")

    def reset(self) -> None:
        self._buf.clear()
        self._expected = 0
        self._stray = 0

    @property
    def pending(self) -> int:
        """Bytes of a packet started but not complete."""
        return len(self._buf)


def wire_time_s(n_bytes: int, baud: int = BAUD) -> float:
    """Time ``n_bytes`` take on an 8N1 line."""
    return n_bytes * BITS_PER_BYTE / baud


def function_name(function: int, from_drive: bool) -> str:
    try:
        return (DriveFunction(function) if from_drive else host_function(function)).name
    except ValueError:
        return f"0x{function:02x}"


def describe(packet: Packet, from_drive: bool) -> str:
    """Human-readable one-line description (used by ``servobus decode`` and ``sniff``)."""
    name = function_name(packet.function, from_drive)
    target = "broadcast" if packet.drive_id == BROADCAST_ID else f"id {packet.drive_id}"
    if from_drive:
        return f"drive {target} -> host: {name} = {packet.reply_value()}"
    extra = ""
    if packet.function == DmmFunction.GENERAL_READ:
        try:
            extra = f" ({GeneralReadSelector(packet.value).name})"
        except ValueError:
            extra = " (unknown selector)"
    spec = HOST_SPECS.get(host_function(packet.function))
    shown = "" if spec is not None and spec.minimum == spec.maximum == 0 else f" {packet.value}"
    return f"host -> {target}: {name}{shown}{extra}"
