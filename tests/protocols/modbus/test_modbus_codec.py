"""Modbus RTU codec: golden frames, CRC and frames cross-checked against pymodbus, properties."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError, ChecksumError, FramingError, ProtocolError
from servobus.protocols.modbus.codec import (
    EXCEPTION_TEXT,
    MAX_READ_COUNT,
    MAX_WRITE_COUNT,
    ExceptionCode,
    ExceptionReply,
    ReadHoldingReply,
    ReadHoldingRequest,
    Reply,
    Request,
    UnsupportedRequest,
    WriteMultipleReply,
    WriteMultipleRequest,
    WriteSingleReply,
    WriteSingleRequest,
    decode_frame,
    decode_reply,
    decode_request,
    describe,
    encode_reply,
    encode_request,
    exception_name,
    expects_reply,
    reply_length,
    request_exception,
)
from servobus.protocols.modbus.crc import crc16, crc_bytes, crc_ok, with_crc

H = bytes.fromhex

# ---------------------------------------------------------------------------------- CRC


def test_crc_check_value() -> None:
    # CRC-16/MODBUS catalogue check value.
    assert crc16(b"123456789") == 0x4B37
    assert crc_bytes(b"123456789") == H("37 4B")


def test_crc_serial_line_spec_example() -> None:
    # Modbus over Serial Line v1.02, appendix B: frame 02 07 carries CRC 0x1241, low byte first.
    assert crc16(H("02 07")) == 0x1241
    assert with_crc(H("02 07")) == H("02 07 41 12")


@settings(deadline=None)
@given(st.binary(min_size=1, max_size=256))
def test_crc_matches_pymodbus(data: bytes) -> None:
    rtu = pytest.importorskip("pymodbus.framer.rtu")
    # pymodbus returns the CRC byte-swapped so that big-endian packing sends the low byte first
    assert crc_bytes(data) == rtu.FramerRTU.compute_CRC(data).to_bytes(2, "big")


@settings(deadline=None)
@given(st.binary(min_size=2, max_size=254))
def test_crc_stays_good_over_a_trailing_zero_byte(data: bytes) -> None:
    # why the framers never take a CRC match alone as the end of a frame (crc.py)
    frame = with_crc(data)
    assert crc_ok(frame + b"\x00")
    assert crc_ok(frame[:-1]) == (frame[-1] == 0)


@settings(deadline=None)
@given(st.binary(min_size=1, max_size=254), st.data())
def test_crc_detects_every_single_bit_error(data: bytes, draw: st.DataObject) -> None:
    frame = bytearray(with_crc(data))
    assert crc_ok(frame)
    bit = draw.draw(st.integers(0, 8 * len(frame) - 1))
    frame[bit // 8] ^= 1 << (bit % 8)
    assert not crc_ok(frame)


# ------------------------------------------------------------------------- golden frames
# Classic frames: the read in the task (01 03 00 00 00 0A C5 CD), the Modbus Application
# Protocol examples of 6.3 / 6.6 / 6.12 / 7 wrapped in RTU as the Modicon PI-MBUS-300 guide
# does (slave 0x11), and the commonly cited one-register read and exception reply.

GOLDEN_REQUESTS: list[tuple[str, Request]] = [
    ("01 03 00 00 00 0A C5 CD", ReadHoldingRequest(1, 0x0000, 10)),
    ("01 03 00 00 00 01 84 0A", ReadHoldingRequest(1, 0x0000, 1)),
    ("11 03 00 6B 00 03 76 87", ReadHoldingRequest(0x11, 0x006B, 3)),
    ("11 06 00 01 00 03 9A 9B", WriteSingleRequest(0x11, 0x0001, 0x0003)),
    ("11 10 00 01 00 02 04 00 0A 01 02 C6 F0", WriteMultipleRequest(0x11, 0x0001, (10, 258))),
]

GOLDEN_REPLIES: list[tuple[str, Reply, Request]] = [
    ("11 03 06 AE 41 56 52 43 40 49 AD", ReadHoldingReply(0x11, (0xAE41, 0x5652, 0x4340)),
     ReadHoldingRequest(0x11, 0x006B, 3)),
    ("11 06 00 01 00 03 9A 9B", WriteSingleReply(0x11, 0x0001, 3),
     WriteSingleRequest(0x11, 0x0001, 3)),
    ("11 10 00 01 00 02 12 98", WriteMultipleReply(0x11, 0x0001, 2),
     WriteMultipleRequest(0x11, 0x0001, (10, 258))),
    ("01 83 02 C0 F1", ExceptionReply(1, 0x03, ExceptionCode.ILLEGAL_DATA_ADDRESS),
     ReadHoldingRequest(1, 0x0100, 1)),
]


@pytest.mark.parametrize(("wire", "request_"), GOLDEN_REQUESTS)
def test_golden_request(wire: str, request_: Request) -> None:
    assert encode_request(request_) == H(wire)
    assert decode_request(H(wire)) == request_
    assert decode_frame(H(wire)) == request_


@pytest.mark.parametrize(("wire", "reply", "request_"), GOLDEN_REPLIES)
def test_golden_reply(wire: str, reply: Reply, request_: Request) -> None:
    assert encode_reply(reply) == H(wire)
    assert decode_reply(H(wire), request_) == reply
    assert decode_reply(bytearray(H(wire)), request_) == reply
    if not isinstance(reply, WriteSingleReply):  # its echo decodes as the request
        assert decode_frame(H(wire)) == reply


# The YZ-AIM spec (004) gives its frame examples for EasyCan only (section V.3 and V.4): the
# same register operations over Modbus RTU, the EasyCan data bytes (little-endian words) taken
# from the spec literally; RTU sends the words big-endian, a two-register write is 0x10.

def _easycan_words(data: str) -> tuple[int, ...]:
    raw = H(data)
    return tuple(int.from_bytes(raw[i:i + 2], "little") for i in range(0, len(raw), 2))


YZAIM_WRITES = [
    # (what, register, EasyCan data bytes from the spec, RTU request, RTU reply)
    ("special function 0x19 = 0 (position mode)", 0x19, "00 00",
     "01 06 00 19 00 00 58 0D", "01 06 00 19 00 00 58 0D"),
    ("parameter save flag 0x14 = 1", 0x14, "01 00",
     "01 06 00 14 00 01 08 0E", "01 06 00 14 00 01 08 0E"),
    ("target speed 1000 rpm, acceleration 10000 rpm/s", 0x02, "E8 03 10 27",
     "01 10 00 02 00 02 04 03 E8 27 10 E8 3A", "01 10 00 02 00 02 E0 08"),
    ("incremental position +32768 (low word first)", 0x0C, "00 80 00 00",
     "01 10 00 0C 00 02 04 80 00 00 00 DA 3A", "01 10 00 0C 00 02 81 CB"),
    ("incremental position -32768", 0x0C, "00 80 FF FF",
     "01 10 00 0C 00 02 04 80 00 FF FF DB 8A", "01 10 00 0C 00 02 81 CB"),
    ("absolute position 65536 (2 turns)", 0x16, "00 00 01 00",
     "01 10 00 16 00 02 04 00 00 00 01 B3 49", "01 10 00 16 00 02 A0 0C"),
    ("absolute position 1 (back to the origin)", 0x16, "01 00 00 00",
     "01 10 00 16 00 02 04 00 01 00 00 23 49", "01 10 00 16 00 02 A0 0C"),
]


@pytest.mark.parametrize(("what", "register", "easycan", "wire", "reply_wire"), YZAIM_WRITES)
def test_yzaim_spec_writes_over_rtu(what: str, register: int, easycan: str, wire: str,
                                    reply_wire: str) -> None:
    words = _easycan_words(easycan)
    request_: Request = (WriteSingleRequest(1, register, words[0]) if len(words) == 1
                         else WriteMultipleRequest(1, register, words))
    assert encode_request(request_) == H(wire), what
    assert decode_request(H(wire)) == request_
    reply = decode_reply(H(reply_wire), request_)
    assert encode_reply(reply) == H(reply_wire)


YZAIM_READS = [
    # spec V.3.a: read one register at 0x00 (value 0), read two (values 0 and 1)
    (ReadHoldingRequest(1, 0x00, 1), "01 03 00 00 00 01 84 0A", "00 00", "01 03 02 00 00 B8 44"),
    (ReadHoldingRequest(1, 0x00, 2), "01 03 00 00 00 02 C4 0B", "00 00 01 00",
     "01 03 04 00 00 00 01 3B F3"),
    # alarm code register 0x0E holding the stall alarm 0x14 (spec 004 section 3, NOTES)
    (ReadHoldingRequest(1, 0x0E, 1), "01 03 00 0E 00 01 E5 C9", "14 00", "01 03 02 00 14 B8 4B"),
    # absolute position 0x16/0x17 = 0x0000370E, the position the spec's write replies return
    (ReadHoldingRequest(1, 0x16, 2), "01 03 00 16 00 02 25 CF", "0E 37 00 00",
     "01 03 04 37 0E 00 00 95 84"),
]


@pytest.mark.parametrize(("request_", "wire", "easycan", "reply_wire"), YZAIM_READS)
def test_yzaim_spec_reads_over_rtu(request_: ReadHoldingRequest, wire: str, easycan: str,
                                   reply_wire: str) -> None:
    assert encode_request(request_) == H(wire)
    reply = ReadHoldingReply(1, _easycan_words(easycan))
    assert encode_reply(reply) == H(reply_wire)
    assert decode_reply(H(reply_wire), request_) == reply


def test_exception_and_broadcast_frames() -> None:
    assert encode_reply(ExceptionReply(1, 0x06, 2)) == H("01 86 02 C3 A1")
    assert encode_reply(ExceptionReply(1, 0x04, 1)) == H("01 84 01 82 C0")
    assert encode_request(WriteSingleRequest(0, 1, 0)) == H("00 06 00 01 00 00 D9 DB")
    assert not expects_reply(WriteSingleRequest(0, 1, 0))
    assert expects_reply(ReadHoldingRequest(1, 0, 1))


# ------------------------------------------------------------------ cross-check: pymodbus


def _pymodbus_frame(message: Request | Reply) -> bytes:
    rtu = pytest.importorskip("pymodbus.framer.rtu")
    pdu = pytest.importorskip("pymodbus.pdu")
    reg = pytest.importorskip("pymodbus.pdu.register_message")
    framer = rtu.FramerRTU(pdu.DecodePDU(False))
    match message:
        case ReadHoldingRequest(address, start, count):
            m = reg.ReadHoldingRegistersRequest(address=start, count=count, dev_id=address)
        case WriteSingleRequest(address, register, value):
            m = reg.WriteSingleRegisterRequest(address=register, registers=[value],
                                               dev_id=address)
        case WriteMultipleRequest(address, start, values):
            m = reg.WriteMultipleRegistersRequest(address=start, registers=list(values),
                                                  dev_id=address)
        case ReadHoldingReply(address, values):
            m = reg.ReadHoldingRegistersResponse(registers=list(values), dev_id=address)
        case WriteMultipleReply(address, start, count):
            m = reg.WriteMultipleRegistersResponse(address=start, count=count, dev_id=address)
        case ExceptionReply(address, function, code):
            m = pdu.ExceptionResponse(function, code, device_id=address)
        case _:
            raise AssertionError(message)
    frame: bytes = framer.buildFrame(m)
    return frame


addresses = st.integers(0, 255)
words = st.integers(0, 0xFFFF)
read_requests = st.builds(ReadHoldingRequest, addresses, st.integers(0, 0xFF00),
                          st.integers(1, MAX_READ_COUNT))
single_requests = st.builds(WriteSingleRequest, addresses, words, words)
multi_requests = st.builds(WriteMultipleRequest, addresses, st.integers(0, 0xFF00),
                           st.lists(words, min_size=1, max_size=MAX_WRITE_COUNT).map(tuple))
requests = st.one_of(read_requests, single_requests, multi_requests)


@settings(deadline=None)
@given(requests)
def test_requests_match_pymodbus(request_: Request) -> None:
    assert encode_request(request_) == _pymodbus_frame(request_)


@settings(deadline=None)
@given(requests, st.data())
def test_replies_match_pymodbus(request_: Request, data: st.DataObject) -> None:
    reply = data.draw(replies_to(request_))
    if not isinstance(reply, WriteSingleReply):  # pymodbus builds it like the request
        assert encode_reply(reply) == _pymodbus_frame(reply)


def test_pymodbus_decodes_our_frames() -> None:
    rtu = pytest.importorskip("pymodbus.framer.rtu")
    pdu = pytest.importorskip("pymodbus.pdu")
    client_side = rtu.FramerRTU(pdu.DecodePDU(False))
    used, got = client_side.handleFrame(encode_reply(ReadHoldingReply(7, (1, 0xFFFF, 2))), 0, 0)
    assert (used, got.dev_id, list(got.registers)) == (11, 7, [1, 0xFFFF, 2])
    server_side = rtu.FramerRTU(pdu.DecodePDU(True))
    frame = encode_request(WriteMultipleRequest(3, 0x16, (0x8000, 0xFFFF)))
    used, got = server_side.handleFrame(frame, 0, 0)
    assert (used, got.dev_id, got.address, list(got.registers)) == (13, 3, 0x16, [0x8000, 0xFFFF])


# ------------------------------------------------------------------ properties: round trip


def replies_to(request_: Request) -> st.SearchStrategy[Reply]:
    exception = st.builds(ExceptionReply, st.just(request_.address),
                          st.just(int(request_.function)), st.integers(0, 0xFF))
    match request_:
        case ReadHoldingRequest(address=a, count=n):
            normal: st.SearchStrategy[Reply] = st.lists(words, min_size=n, max_size=n).map(
                lambda v: ReadHoldingReply(a, tuple(v)))
        case WriteSingleRequest(address=a, register=r):
            normal = st.builds(WriteSingleReply, st.just(a), st.just(r), words)
        case WriteMultipleRequest(address=a, start=s, values=v):
            normal = st.just(WriteMultipleReply(a, s, len(v)))
    return st.one_of(normal, exception)


@settings(deadline=None)
@given(requests)
def test_request_round_trip(request_: Request) -> None:
    wire = encode_request(request_)
    assert decode_request(wire) == request_
    assert decode_frame(wire) == request_
    assert request_exception(request_) is None
    assert isinstance(describe(wire), str)


@settings(deadline=None)
@given(requests, st.data())
def test_reply_round_trip(request_: Request, data: st.DataObject) -> None:
    reply = data.draw(replies_to(request_))
    wire = encode_reply(reply)
    assert decode_reply(wire, request_) == reply
    if not isinstance(reply, ExceptionReply):
        assert len(wire) == reply_length(request_)
    else:
        assert len(wire) == 5
    assert isinstance(describe(wire), str)


@settings(deadline=None)
@given(st.binary(max_size=300))
def test_decoders_raise_only_protocol_errors_on_any_bytes(raw: bytes) -> None:
    for attempt in (raw, with_crc(raw)):  # with a good CRC the structure checks run too
        for decode in (decode_request, decode_frame, describe,
                       lambda f: decode_reply(f, ReadHoldingRequest(1, 0, 2))):
            with contextlib.suppress(ProtocolError):
                decode(attempt)


@settings(deadline=None)
@given(st.binary(min_size=2, max_size=254))
def test_frames_with_a_good_crc_never_fail_the_checksum(body: bytes) -> None:
    try:
        decoded = decode_frame(with_crc(body))
    except ChecksumError:
        pytest.fail("a frame with a good CRC raised ChecksumError")
    except ProtocolError:
        return
    assert decoded.address == body[0]


# ------------------------------------------------------------------------------- errors


def test_bad_crc_raises_checksum_error_with_the_bytes() -> None:
    raw = H("01 03 00 00 00 0A C5 CC")
    with pytest.raises(ChecksumError) as err:
        decode_request(raw)
    assert err.value.raw == raw
    with pytest.raises(ChecksumError):
        decode_reply(H("11 03 06 AE 41 56 52 43 40 49 AE"), ReadHoldingRequest(0x11, 0x6B, 3))


@pytest.mark.parametrize("body", [
    "01 03 00 00 00",  # read request one byte short
    "01 06 00 01 00 03 00",  # write-single request one byte long
    "01 10 00 01 00 02 04 00 0A 01",  # byte count says 4, 3 follow
    "01 10 00 01 00 02 02 00 0A",  # byte count 2 for 2 registers
    "01 83 02 00",  # exception reply one byte long
])
def test_malformed_requests_raise_framing_error(body: str) -> None:
    with pytest.raises(FramingError):
        decode_frame(with_crc(H(body)))


@pytest.mark.parametrize("raw", [b"", b"\x01", b"\x01\x03\xff", bytes(257)])
def test_frame_length_outside_4_to_256_raises_framing_error(raw: bytes) -> None:
    with pytest.raises(FramingError):
        decode_request(raw)


@pytest.mark.parametrize(("body", "request_"), [
    ("02 03 02 00 00", ReadHoldingRequest(1, 0, 1)),  # another address
    ("01 04 02 00 00", ReadHoldingRequest(1, 0, 1)),  # another function
    ("01 84 02", ReadHoldingRequest(1, 0, 1)),  # exception to another function
    ("01 03 04 00 00 00 00", ReadHoldingRequest(1, 0, 1)),  # two registers for a read of one
    ("01 06 00 02 00 00", WriteSingleRequest(1, 1, 0)),  # echo of another register
    ("01 10 00 01 00 03", WriteMultipleRequest(1, 1, (1, 2))),  # another count
])
def test_reply_that_does_not_answer_the_request(body: str, request_: Request) -> None:
    with pytest.raises(ProtocolError) as err:
        decode_reply(with_crc(H(body)), request_)
    assert not isinstance(err.value, ChecksumError)


def test_write_single_reply_value_may_differ_from_the_written_one() -> None:
    # decision in the codec docstring: the register must match, the value is reported as is
    reply = decode_reply(with_crc(H("01 06 00 0C 37 0E")), WriteSingleRequest(1, 0x0C, 5))
    assert reply == WriteSingleReply(1, 0x0C, 0x370E)


@pytest.mark.parametrize("bad", [
    ReadHoldingRequest(1, 0, 0),
    ReadHoldingRequest(1, 0, MAX_READ_COUNT + 1),
    ReadHoldingRequest(1, 0xFFFF, 2),
    ReadHoldingRequest(256, 0, 1),
    ReadHoldingRequest(-1, 0, 1),
    WriteSingleRequest(1, 0x10000, 0),
    WriteSingleRequest(1, 0, 0x10000),
    WriteSingleRequest(1, 0, -1),
    WriteMultipleRequest(1, 0, ()),
    WriteMultipleRequest(1, 0, (0,) * (MAX_WRITE_COUNT + 1)),
    WriteMultipleRequest(1, 0, (0, 0x10000)),
    UnsupportedRequest(1, 0x100, b""),
])
def test_out_of_range_requests_are_refused(bad: Request | UnsupportedRequest) -> None:
    with pytest.raises(ArgumentRangeError):
        encode_request(bad)


@pytest.mark.parametrize("bad", [
    ReadHoldingReply(1, ()),
    ReadHoldingReply(1, (0,) * (MAX_READ_COUNT + 1)),
    ReadHoldingReply(1, (0x10000,)),
    WriteSingleReply(1, 0, 0x10000),
    WriteMultipleReply(1, 0, 0),
    ExceptionReply(1, 0x80, 1),
    ExceptionReply(1, 3, 0x100),
])
def test_out_of_range_replies_are_refused(bad: Reply) -> None:
    with pytest.raises(ArgumentRangeError):
        encode_reply(bad)


# ---------------------------------------------------------- server-side request checks


def test_unsupported_function_decodes_and_gets_illegal_function() -> None:
    raw = with_crc(H("01 04 00 00 00 01"))  # read input registers
    request_ = decode_request(raw)
    assert request_ == UnsupportedRequest(1, 0x04, H("00 00 00 01"))
    assert encode_request(request_) == raw
    assert request_exception(request_) is ExceptionCode.ILLEGAL_FUNCTION
    assert encode_reply(ExceptionReply(1, 0x04, request_exception(request_) or 0)) == \
        H("01 84 01 82 C0")


@pytest.mark.parametrize(("body", "code"), [
    ("01 03 00 00 00 00", ExceptionCode.ILLEGAL_DATA_VALUE),  # count 0
    ("01 03 00 00 00 7E", ExceptionCode.ILLEGAL_DATA_VALUE),  # count 126
    ("01 03 FF FF 00 02", ExceptionCode.ILLEGAL_DATA_ADDRESS),  # past 0xFFFF
    ("01 10 00 00 00 00 00", ExceptionCode.ILLEGAL_DATA_VALUE),  # write of no register
    ("01 10 FF FF 00 02 04 00 00 00 00", ExceptionCode.ILLEGAL_DATA_ADDRESS),
])
def test_request_exception_per_the_standard(body: str, code: ExceptionCode) -> None:
    assert request_exception(decode_request(with_crc(H(body)))) is code


def test_exception_names_come_from_one_table() -> None:
    assert set(EXCEPTION_TEXT) == set(ExceptionCode)
    assert ExceptionReply(1, 3, 2).name == "ILLEGAL_DATA_ADDRESS"
    assert [exception_name(c) for c in (1, 2, 3, 4)] == [
        "ILLEGAL_FUNCTION", "ILLEGAL_DATA_ADDRESS", "ILLEGAL_DATA_VALUE", "SERVER_DEVICE_FAILURE"]
    assert exception_name(0x07) == "code 0x07"


# ------------------------------------------------------------------------------ describe


@pytest.mark.parametrize(("wire", "text"), [
    ("01 03 00 00 00 0A C5 CD", "id 1 read 0x0000 alarm x10"),
    ("01 03 00 0E 00 01 E5 C9", "id 1 read 0x000E"),
    ("11 03 06 AE 41 56 52 43 40 49 AD", "id 17 read reply [44609, 22098, 17216]"),
    ("01 06 00 19 00 00 58 0D", "id 1 write 0x0019=0 (request or echo)"),
    ("01 10 00 02 00 02 04 03 E8 27 10 E8 3A", "id 1 write 0x0002=1000, 0x0003=10000"),
    ("01 10 00 02 00 02 E0 08", "id 1 wrote 2 registers from 0x0002"),
    ("00 06 00 01 00 00 D9 DB", "broadcast write 0x0001=0 (request or echo)"),
    ("01 83 02 C0 F1", "id 1 exception ILLEGAL_DATA_ADDRESS to read holding registers: "
                       "register address (or address + count) not allowed"),
    ("01 84 01 82 C0", "id 1 exception ILLEGAL_FUNCTION to function 0x04: "
                       "function code not supported by the device"),
    ("01 86 07 03 A2", "id 1 exception code 0x07 to write single register"),
    ("07 2B 0E 01 00 F8 77", "id 7 function 0x2B data 0e 01 00"),
])
def test_describe(wire: str, text: str) -> None:
    assert describe(H(wire), {0x0000: "alarm"}) == text


def test_describe_raises_typed_errors() -> None:
    with pytest.raises(ChecksumError):
        describe(H("01 03 00 00 00 0A C5 CE"))
    with pytest.raises(FramingError):
        describe(H("01 03"))


# ------------------------------------------------------- with the YZ-AIM family's table


@pytest.mark.parametrize(("name", "value", "easycan", "wire"), [
    ("incremental_position", 32768, "00 80 00 00", "01 10 00 0C 00 02 04 80 00 00 00 DA 3A"),
    ("incremental_position", -32768, "00 80 FF FF", "01 10 00 0C 00 02 04 80 00 FF FF DB 8A"),
    ("absolute_position", 65536, "00 00 01 00", "01 10 00 16 00 02 04 00 00 00 01 B3 49"),
    ("target_speed", 1000, "E8 03", "01 06 00 02 03 E8 28 B4"),
    ("special_function", 0, "00 00", "01 06 00 19 00 00 58 0D"),
])
def test_yzaim_parameters_through_the_family_table(name: str, value: int, easycan: str,
                                                   wire: str) -> None:
    yzaim = pytest.importorskip("servobus.families.yzaim.registers")
    start, words_ = yzaim.encode_parameter(name, value)
    assert words_ == _easycan_words(easycan)  # the same words EasyCan sends little-endian
    request_: Request = (WriteSingleRequest(1, start, words_[0]) if len(words_) == 1
                         else WriteMultipleRequest(1, start, words_))
    assert encode_request(request_) == H(wire)
    names = {r.address: r.name for r in yzaim.REGISTERS}
    assert names[start] in describe(H(wire), names)
