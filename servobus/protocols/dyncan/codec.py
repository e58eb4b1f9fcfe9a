"""DYN CAN frames (DYN CAN specification 1.2A, sections 4-6). Pure: (id, data) <-> Frame.

CAN 2.0A base frames, 1..5 data bytes (group 3 carries 5)::

    11-bit identifier = drive id << 5 | function code     b10..b5 drive id, b4..b0 FC

Decisions (docs/dyncan.md; the manual is silent):

* multi-byte data is big-endian two's complement, encoded with the fewest bytes the
  table allows; any length in the table's range decodes;
* a reply reuses the request's identifier (drive id << 5 | FC); the reply to
  ``General_Read`` comes on 0x0E;
* id 0 is the broadcast id, drive ids are 1..63 (six identifier bits);
* ``Set_Origin`` is accepted with 0 data bytes or 1 byte 0xFF;
* parameter groups are fixed unsigned big-endian fields where 0 means "leave unchanged";
* ``General_Read`` takes the same one-byte selectors as on DYN232M (the CAN manual names
  0x1B position and 0x1E torque, the values DMM's DYN232M library uses too; servobus also
  serves 0x1D speed and the 0x1C reset / 0x20 enable / 0x21 disable actions there).

One table, :data:`SPECS`, holds every function's data lengths, layout and range; the
client range-checks and the virtual node answers Drive Error 0xFF from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum

from servobus.errors import ArgumentRangeError, FramingError
from servobus.families.dmm import params as P
from servobus.families.dmm.vocabulary import (
    CONST_SPEED_LIMIT_RPM,
    VALUE_MAX,
    VALUE_MIN,
    WAVE_AMPLITUDE_MAX,
    WAVE_FREQUENCY_MAX_HZ,
    DmmFunction,
    GeneralReadSelector,
)
from servobus.families.dmm.vocabulary import (
    MAX_DRIVE_ID as MAX_DRIVE_ID,  # six identifier bits
)
from servobus.families.dmm.vocabulary import (
    Kind as Kind,  # re-exported: the DMM command kinds
)

BROADCAST_ID = 0
MIN_DRIVE_ID = 1
ASSIGN_ID_MAX = 64  # the range the manual checks (Drive Error outside 0..64)
FUNCTION_BITS = 5
MAX_ARBITRATION_ID = 0x7FF
MAX_DATA = 8
POSITION_DIRECT_LIMIT = 16_384
ORIGIN_CODE = 0xFF  # Set_Origin's one data byte (section 6)
BITRATES_KBIT = (10, 20, 50, 125, 250, 500, 800, 1000)


class Function(IntEnum):
    """DYN CAN's own function codes (section 5), 0x10-0x1F. 0x00-0x0F are the shared DMM
    codes, :class:`~servobus.families.dmm.vocabulary.DmmFunction` (one enum for both DMM
    protocols)."""

    SET_PARAM_GROUP1 = 0x10
    SET_PARAM_GROUP2 = 0x11
    SET_PARAM_GROUP3 = 0x12
    READ_PARAM_GROUP1 = 0x13
    READ_PARAM_GROUP2 = 0x14
    READ_PARAM_GROUP3 = 0x15
    GO_ABSOLUTE_POS_SYNC = 0x16
    GO_RELATIVE_POS_SYNC = 0x17
    SYNC_TRIGGER = 0x18
    SERVO_DISABLE = 0x19
    READ_MOTOR_SPEED = 0x1A
    TBD = 0x1B
    POSITION_DIRECT = 0x1C  # Go_Relative_Pos_PD
    DRIVE_ERROR = 0x1D
    ECHO = 0x1E
    DIAGNOSTIC_COUNTER = 0x1F


#: A DYN CAN function code: a shared DMM code or one of DYN CAN's own.
Code = DmmFunction | Function
#: Every function code, 0x00..0x1F in order.
FUNCTIONS: tuple[Code, ...] = (*DmmFunction, *Function)


def function_of(code: int) -> Code:
    """The function of a 5-bit code (ValueError for a code no enum has)."""
    return DmmFunction(code) if code < Function.SET_PARAM_GROUP1 else Function(code)


class DriveErrorCode(IntEnum):
    """Data byte of Drive Error (0x1D), always sent by the drive."""

    INVALID_DATA = 0xFF  # answers a request whose data is outside the allowed range
    ALARM = 0xEE  # pushed unsolicited when the drive alarms


class SyncTrigger(IntEnum):
    ABSOLUTE = 0xFF  # start the loaded Go_Absolute_Pos_Sync
    RELATIVE = 0xEE  # start the loaded Go_Relative_Pos_Sync


class ServoCommand(IntEnum):
    ENABLE = 0x00
    DISABLE = 0xFF


class Layout(Enum):
    """How a function's data bytes carry its value."""

    NONE = "none"  # no data
    SIGNED = "signed"  # one big-endian two's complement number
    BYTE = "byte"  # one unsigned byte (register, counter, code)
    FIELDS = "fields"  # fixed unsigned big-endian fields; 0 = leave unchanged
    RAW = "raw"  # bytes as they are (echo)


@dataclass(frozen=True)
class Field:
    param: str  # servobus.families.dmm.params name: its range applies
    width: int  # bytes


@dataclass(frozen=True)
class FunctionSpec:
    function: Code
    kind: Kind
    request: Layout
    sent: tuple[int, int]  # data bytes host -> drive (min, max)
    reply: Layout | None  # None: the drive does not answer
    returned: tuple[int, int] = (0, 0)
    minimum: int = 0  # allowed request value (SIGNED / BYTE layouts)
    maximum: int = 0
    codes: tuple[int, ...] = ()  # a BYTE request that only takes these codes
    fields: tuple[Field, ...] = ()
    drive_error: bool = False  # the manual says the drive answers Drive Error 0xFF
    doc: str = ""
    #: Dummy bytes a host may send with a data-less read: the manual's "Total Data" column
    #: counts them (e.g. Read_Drive_Config 1, Read_Param_Group3 2). Accepted and ignored.
    dummy: int = 0

    def accepts_length(self, n_bytes: int) -> bool:
        """A request of ``n_bytes`` data bytes has this function's shape (dummies included)."""
        lo, hi = self.sent
        return lo <= n_bytes <= hi or (self.request is Layout.NONE and n_bytes <= self.dummy)

    @property
    def expects_reply(self) -> bool:
        return self.reply is not None

    def accepts(self, value: int) -> bool:
        """Is ``value`` inside this function's request range (SIGNED / BYTE layouts)."""
        if self.codes:
            return value in self.codes
        return self.minimum <= value <= self.maximum


_D, _F, _K, _L = DmmFunction, Function, Kind, Layout
_POS = (VALUE_MIN, VALUE_MAX)
_G1 = (Field("main_gain", 1), Field("speed_gain", 1), Field("int_gain", 1), Field("trq_cons", 1))
_G2 = (Field("max_speed", 1), Field("max_accel", 1))
_G3 = (Field("on_range", 1), Field("gear_num", 2), Field("line_num", 2))
_SELECTORS = tuple(int(s) for s in GeneralReadSelector)


def _motion(fn: Code, lengths: tuple[int, int], lo: int, hi: int, doc: str,
            drive_error: bool = True) -> FunctionSpec:
    return FunctionSpec(fn, _K.MOTION, _L.SIGNED, lengths, None, minimum=lo, maximum=hi,
                        drive_error=drive_error, doc=doc)


def _group_read(fn: Function, fields: tuple[Field, ...], doc: str, dummy: int) -> FunctionSpec:
    n = sum(f.width for f in fields)
    return FunctionSpec(fn, _K.READ, _L.NONE, (0, 0), _L.FIELDS, (n, n), fields=fields, doc=doc,
                        dummy=dummy)


def _group_set(fn: Function, fields: tuple[Field, ...], doc: str) -> FunctionSpec:
    n = sum(f.width for f in fields)
    return FunctionSpec(fn, _K.SETTING, _L.FIELDS, (n, n), None, fields=fields,
                        drive_error=True, doc=doc)


#: THE DYN CAN function table (section 5, corrected by section 6 and docs/errata.md).
SPECS: dict[Code, FunctionSpec] = {
    s.function: s
    for s in (
        FunctionSpec(_D.SET_ORIGIN, _K.ACTION, _L.BYTE, (0, 1), None, minimum=ORIGIN_CODE,
                     maximum=ORIGIN_CODE, codes=(ORIGIN_CODE,),
                     doc="current position becomes absolute zero (0 or 1 byte 0xFF)"),
        _motion(_D.GO_ABSOLUTE_POS, (1, 4), *_POS, "point-to-point absolute move"),
        _motion(_D.MAKE_LINEAR_LINE, (1, 4), *_POS, "3-axis linear interpolation word"),
        _motion(_D.GO_RELATIVE_POS, (1, 4), *_POS, "point-to-point relative move"),
        _motion(_D.MAKE_CIRCULAR_ARC, (1, 4), *_POS, "3-axis circular interpolation word"),
        FunctionSpec(_D.ASSIGN_DRIVE_ID, _K.SETTING, _L.BYTE, (1, 1), None, minimum=0,
                     maximum=ASSIGN_ID_MAX, drive_error=True,
                     doc="new drive id; wait 10 ms for the CAN port to re-initialise"),
        FunctionSpec(_D.READ_DRIVE_ID, _K.READ, _L.NONE, (0, 0), _L.BYTE, (1, 1),
                     doc="drive id"),
        FunctionSpec(_D.SET_DRIVE_CONFIG, _K.SETTING, _L.BYTE, (1, 1), None, minimum=0,
                     maximum=0xFF, doc="configuration byte (b7 b6 unimplemented)"),
        FunctionSpec(_D.READ_DRIVE_CONFIG, _K.READ, _L.NONE, (0, 0), _L.BYTE, (1, 1),
                     doc="configuration byte", dummy=1),
        FunctionSpec(_D.READ_DRIVE_STATUS, _K.READ, _L.NONE, (0, 0), _L.BYTE, (1, 1),
                     doc="status byte"),
        _motion(_D.TURN_CONST_SPEED, (1, 2), -CONST_SPEED_LIMIT_RPM, CONST_SPEED_LIMIT_RPM,
                "rpm, positive CW"),
        _motion(_D.SQUARE_WAVE, (1, 3), 0, WAVE_AMPLITUDE_MAX, "amplitude, 4096 = 180 deg"),
        _motion(_D.SIN_WAVE, (1, 3), 0, WAVE_AMPLITUDE_MAX, "amplitude, 4096 = 180 deg"),
        _motion(_D.SS_FREQUENCY, (1, 1), 0, WAVE_FREQUENCY_MAX_HZ, "wave frequency, Hz"),
        FunctionSpec(_D.GENERAL_READ, _K.READ, _L.BYTE, (1, 1), _L.SIGNED, (1, 4),
                     minimum=min(_SELECTORS), maximum=max(_SELECTORS), codes=_SELECTORS,
                     doc="selector 0x1B position (counts), 0x1E torque (700 = peak)"),
        FunctionSpec(_D.FOR_MOTOR_DEFINE, _K.INTERNAL, _L.RAW, (0, 0), None,
                     doc="DMM internal; never sent"),
        _group_set(_F.SET_PARAM_GROUP1, _G1, "main, speed, integration gain, torque filter"),
        _group_set(_F.SET_PARAM_GROUP2, _G2, "max speed, max acceleration"),
        _group_set(_F.SET_PARAM_GROUP3, _G3, "on-position range, GEAR_NUM, LINE_NUM"),
        _group_read(_F.READ_PARAM_GROUP1, _G1, "main, speed, integration gain, torque filter",
                    dummy=1),
        _group_read(_F.READ_PARAM_GROUP2, _G2, "max speed, max acceleration", dummy=1),
        _group_read(_F.READ_PARAM_GROUP3, _G3, "on-position range, GEAR_NUM, LINE_NUM",
                    dummy=2),
        _motion(_F.GO_ABSOLUTE_POS_SYNC, (1, 4), *_POS, "load absolute move; Sync_Trigger 0xFF"),
        _motion(_F.GO_RELATIVE_POS_SYNC, (1, 4), *_POS, "load relative move; Sync_Trigger 0xEE"),
        FunctionSpec(_F.SYNC_TRIGGER, _K.MOTION, _L.BYTE, (1, 1), None,
                     minimum=min(SyncTrigger), maximum=max(SyncTrigger),
                     codes=tuple(int(c) for c in SyncTrigger), doc="start loaded sync moves"),
        FunctionSpec(_F.SERVO_DISABLE, _K.ACTION, _L.BYTE, (1, 1), None,
                     minimum=min(ServoCommand), maximum=max(ServoCommand),
                     codes=tuple(int(c) for c in ServoCommand), doc="0x00 enable, 0xFF disable"),
        FunctionSpec(_F.READ_MOTOR_SPEED, _K.READ, _L.NONE, (0, 0), _L.SIGNED, (2, 2),
                     doc="motor speed, rpm", dummy=2),
        FunctionSpec(_F.TBD, _K.INTERNAL, _L.RAW, (0, 0), None, doc="empty command"),
        # The manual lists no Drive Error for Position Direct: out-of-range PD is ignored.
        _motion(_F.POSITION_DIRECT, (1, 2), -POSITION_DIRECT_LIMIT, POSITION_DIRECT_LIMIT,
                "position direct relative step (no profile)", drive_error=False),
        FunctionSpec(_F.DRIVE_ERROR, _K.INTERNAL, _L.NONE, (0, 0), _L.BYTE, (1, 1),
                     doc="drive -> host: 0xFF invalid data, 0xEE alarm"),
        FunctionSpec(_F.ECHO, _K.READ, _L.RAW, (4, 4), _L.RAW, (4, 4), doc="4-byte echo"),
        FunctionSpec(_F.DIAGNOSTIC_COUNTER, _K.READ, _L.NONE, (0, 0), _L.BYTE, (1, 1),
                     doc="8-bit counter, +1 per read, wraps after 255", dummy=1),
    )
}
assert len(SPECS) == 32

#: Parameter name -> (set group function, read group function, field index).
PARAM_GROUPS: dict[str, tuple[Code, Code, int]] = {
    f.param: (
        s.function,
        next(r.function for r in SPECS.values()
             if r.kind is Kind.READ and r.fields == s.fields),
        i,
    )
    for s in SPECS.values() if s.kind is Kind.SETTING and s.fields
    for i, f in enumerate(s.fields)
}

#: General_Read selectors the drive answers (on function 0x0E).
GENERAL_READ_ANSWERED: frozenset[GeneralReadSelector] = frozenset(
    {GeneralReadSelector.POSITION, GeneralReadSelector.SPEED, GeneralReadSelector.TORQUE}
)


# ------------------------------------------------------------------ identifiers
def arbitration_id(drive_id: int, function: int) -> int:
    if not 0 <= drive_id <= MAX_DRIVE_ID:
        raise ArgumentRangeError(f"drive id {drive_id} is outside 0..{MAX_DRIVE_ID}")
    if not 0 <= function <= 0x1F:
        raise ArgumentRangeError(f"function code {function} is outside 0x00..0x1F")
    return (drive_id << FUNCTION_BITS) | function


def split_id(arbitration_id: int) -> tuple[int, int]:
    """(drive id, function code) of an 11-bit identifier."""
    if not 0 <= arbitration_id <= MAX_ARBITRATION_ID:
        raise FramingError(f"identifier 0x{arbitration_id:x} is not an 11-bit base id")
    return arbitration_id >> FUNCTION_BITS, arbitration_id & 0x1F


# ------------------------------------------------------------------ numbers
def signed_length(value: int, lengths: tuple[int, int] = (1, 4)) -> int:
    """Fewest bytes in ``lengths`` that hold ``value`` as two's complement."""
    lo, hi = lengths
    for n in range(max(lo, 1), hi + 1):
        lim = 1 << (8 * n - 1)
        if -lim <= value < lim:
            return n
    raise ArgumentRangeError(f"value {value} does not fit in {hi} signed byte(s)")


def encode_signed(value: int, lengths: tuple[int, int] = (1, 4)) -> bytes:
    return value.to_bytes(signed_length(value, lengths), "big", signed=True)


def decode_signed(data: bytes) -> int:
    return int.from_bytes(data, "big", signed=True) if data else 0


def pack_fields(fields: tuple[Field, ...], values: tuple[int, ...]) -> bytes:
    """Group data; 0 = leave unchanged. Values must fit their width (ranges: see check)."""
    if len(values) != len(fields):
        raise ArgumentRangeError(f"expected {len(fields)} values, got {len(values)}")
    out = bytearray()
    for f, v in zip(fields, values, strict=True):
        if not 0 <= v < 1 << (8 * f.width):
            raise ArgumentRangeError(f"{f.param}={v} does not fit in {f.width} unsigned byte(s)")
        out += v.to_bytes(f.width, "big")
    return bytes(out)


def unpack_fields(fields: tuple[Field, ...], data: bytes) -> tuple[int, ...]:
    n = sum(f.width for f in fields)
    if len(data) != n:
        raise FramingError(f"parameter group needs {n} data bytes, got {len(data)}")
    out, i = [], 0
    for f in fields:
        out.append(int.from_bytes(data[i:i + f.width], "big"))
        i += f.width
    return tuple(out)


def field_valid(field: Field, value: int) -> bool:
    """A group value is valid when 0 (unchanged) or inside the parameter's range."""
    return value == 0 or P.spec(field.param).valid(value)


# ------------------------------------------------------------------ frames
@dataclass(frozen=True)
class Frame:
    """One DYN CAN frame: the identifier split into drive id and function code."""

    drive_id: int
    function: int
    data: bytes = b""

    @property
    def arbitration_id(self) -> int:
        return arbitration_id(self.drive_id, self.function)

    @property
    def spec(self) -> FunctionSpec:
        return SPECS[self.function]  # type: ignore[index]  # IntEnum keys hash as ints

    @property
    def value(self) -> int:
        """Data as one big-endian signed number."""
        return decode_signed(self.data)

    @property
    def unsigned(self) -> int:
        return int.from_bytes(self.data, "big")

    def fields(self) -> tuple[int, ...]:
        return unpack_fields(self.spec.fields, self.data)

    def describe(self, from_drive: bool) -> str:
        """One line for traces, ``decode`` and ``sniff`` (see :func:`describe`)."""
        return describe(self, from_drive)


def encode(frame: Frame) -> tuple[int, bytes]:
    """(arbitration id, data) ready for any CAN library."""
    if len(frame.data) > MAX_DATA:
        raise ArgumentRangeError(f"{len(frame.data)} data bytes exceed a CAN frame's 8")
    return frame.arbitration_id, bytes(frame.data)


def decode(arbitration_id: int, data: bytes | bytearray) -> Frame:
    """Frame from an identifier and data; FramingError for non-DYN-CAN frames."""
    drive_id, function = split_id(arbitration_id)
    if len(data) > MAX_DATA:
        raise FramingError(f"{len(data)} data bytes exceed a CAN frame's 8")
    return Frame(drive_id, function, bytes(data))


def request(drive_id: int, function: Code, value: int | None = None,
            fields: tuple[int, ...] | None = None, raw: bytes | None = None) -> Frame:
    """Host request with the table's layout; structural checks only (fits the bytes).

    Ranges are checked by the client (servobus.protocols.dyncan.commands) so the simulator
    can still be fed out-of-range data in tests.
    """
    spec = SPECS[function]
    lay = spec.request
    if lay is Layout.NONE:
        data = b""
    elif lay is Layout.SIGNED:
        data = encode_signed(0 if value is None else value, spec.sent)
    elif lay is Layout.BYTE:
        if value is None:
            data = b""
        elif not 0 <= value <= 0xFF:
            raise ArgumentRangeError(f"{function.name} data {value} is not one byte")
        else:
            data = bytes((value,))
    elif lay is Layout.FIELDS:
        data = pack_fields(spec.fields, fields if fields is not None else (0,) * len(spec.fields))
    else:
        data = raw if raw is not None else b"\x00" * spec.sent[0]
    return Frame(drive_id, function, data)


def reply(drive_id: int, function: Code, value: int | None = None,
          fields: tuple[int, ...] | None = None, raw: bytes | None = None) -> Frame:
    """Drive reply on the request's identifier, with the table's reply layout."""
    spec = SPECS[function]
    lay = spec.reply
    if lay is Layout.SIGNED:
        data = encode_signed(0 if value is None else value, spec.returned)
    elif lay is Layout.BYTE:
        data = bytes(((value or 0) & 0xFF,))
    elif lay is Layout.FIELDS:
        data = pack_fields(spec.fields, fields or ())
    elif lay is Layout.RAW:
        data = raw or b""
    else:
        raise ArgumentRangeError(f"{function.name} has no reply")
    return Frame(drive_id, function, data)


def drive_error(drive_id: int, code: DriveErrorCode) -> Frame:
    return Frame(drive_id, Function.DRIVE_ERROR, bytes((code,)))


_ANSWERED_CODES = frozenset(int(s) for s in GENERAL_READ_ANSWERED)
_REPLY_LENGTHS: dict[int, tuple[int, int]] = {
    int(f): s.returned for f, s in SPECS.items() if s.reply is not None}


def expects_reply(frame: Frame) -> bool:
    """Will the drive answer this request (General_Read: only the reading selectors)."""
    if frame.function not in _REPLY_LENGTHS:
        return False
    if frame.function == DmmFunction.GENERAL_READ:
        return bool(frame.data) and frame.data[0] in _ANSWERED_CODES
    return True


def is_reply_shape(frame: Frame) -> bool:
    """Does the frame's data length fit the table's reply (tells a reply from its request)."""
    lengths = _REPLY_LENGTHS.get(frame.function)
    if lengths is None:
        return False
    return lengths[0] <= len(frame.data) <= lengths[1]


# ------------------------------------------------------------------ text
def function_name(function: int) -> str:
    try:
        return function_of(function).name
    except ValueError:
        return f"0x{function:02x}"


def _looks_like_reply(frame: Frame, spec: FunctionSpec) -> bool:
    """Guess the direction of a frame seen on the bus (replies reuse the identifier)."""
    if frame.function == Function.DRIVE_ERROR:
        return True
    if spec.reply is None or spec.request is Layout.RAW:
        return False  # echo: identical both ways, shown as the request
    lo, hi = spec.sent
    if not lo <= len(frame.data) <= hi:
        return True
    return spec.request is Layout.BYTE and bool(frame.data) and frame.data[0] not in spec.codes


def _show(frame: Frame, layout: Layout | None, spec: FunctionSpec) -> str:
    if layout is Layout.SIGNED:
        return f" {frame.value}"
    if layout is Layout.BYTE and frame.data:
        return f" 0x{frame.data[0]:02x}"
    if layout is Layout.FIELDS:
        try:
            vals = unpack_fields(spec.fields, frame.data)
        except FramingError as exc:
            return f" ({exc})"
        unchanged = layout is spec.request  # in a group write 0 = leave unchanged
        shown = ["unchanged" if unchanged and v == 0 else str(v) for v in vals]
        return " " + ", ".join(f"{f.param}={v}" for f, v in zip(spec.fields, shown, strict=True))
    if layout is Layout.RAW and frame.data:
        return " " + frame.data.hex(" ")
    return ""


def describe(frame: Frame, from_drive: bool | None = None) -> str:
    """One line for ``servobus decode`` / ``sniff``; direction guessed when None."""
    name = function_name(frame.function)
    try:
        spec = SPECS[function_of(frame.function)]
    except ValueError:  # pragma: no cover - 5 bits always name a function
        return f"id 0x{frame.arbitration_id:03x}: {frame.data.hex(' ')}"
    if from_drive is None:
        from_drive = _looks_like_reply(frame, spec)
    target = "broadcast" if frame.drive_id == BROADCAST_ID else f"id {frame.drive_id}"
    if from_drive:
        if frame.function == Function.DRIVE_ERROR and frame.data:
            try:
                what = DriveErrorCode(frame.data[0]).name
            except ValueError:
                what = f"0x{frame.data[0]:02x}"
            return f"drive {target} -> host: DRIVE_ERROR {what}"
        return f"drive {target} -> host: {name}{_show(frame, spec.reply, spec)}"
    extra = ""
    if frame.function == DmmFunction.GENERAL_READ and frame.data:
        try:
            extra = f" ({GeneralReadSelector(frame.data[0]).name})"
        except ValueError:
            extra = " (unknown selector)"
    elif frame.function == Function.SYNC_TRIGGER and frame.data:
        try:
            extra = f" ({SyncTrigger(frame.data[0]).name})"
        except ValueError:
            extra = " (unknown trigger)"
    elif frame.function == Function.SERVO_DISABLE and frame.data:
        try:
            extra = f" ({ServoCommand(frame.data[0]).name})"
        except ValueError:
            extra = " (unknown)"
    return f"host -> {target}: {name}{_show(frame, spec.request, spec)}{extra}"
