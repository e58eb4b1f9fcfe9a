"""EasyCan codec: every frame example of the YZ-AIM manual byte for byte, property tests
for every encode/decode pair, malformed frames -> typed errors only.

Golden frames (YZ-AIM EasyCan v3.5 manual; (identifier, data)):
  5.3a  read one register        01: FF 03 00 01          -> FF: 01 03 00 01 00 00
  5.3a  read two registers       01: FF 03 00 02          -> FF: 01 03 00 02 00 00 01 00
  5.3b  write one register       01: FF 06 00 01 01 00    -> FF: 01 06 00 01 01 00
  5.3b  write two registers      01: FF 06 00 02 01 00 01 00 -> FF: (same, from 01)
  5.3c  cache write, no reply    101: 00 00 00 00
  5.3c  cache write with reply   301: 00 00 00 00         -> FF: 00 00 00 00
  5.3d  emergency stop           01: FF 10                -> FF: 01 10
  5.3e  absolute position clear  01: FF 11 (DLC 4)           no reply
  5.3f  read three registers     01: FF 12 00 01 02       -> FF: 01 12 01 00 01 00 01 00
  5.4a  special function 0       01: FF 06 19 01 00 00    -> FF: 01 06 19 01 00 00
  5.4a  save flag 1              01: FF 06 14 01 01 00    -> FF: 01 06 14 01 01 00
  5.4a  speed 1000, accel 10000  01: FF 06 02 02 E8 03 10 27 -> FF: 01 06 02 02 E8 03 10 27
  5.4a  incremental +32768       01: FF 06 0C 02 00 80 00 00 -> FF: 01 06 0C 02 0E 37 00 00
  5.4a  incremental -32768       01: FF 06 0C 02 00 80 FF FF -> FF: 01 06 0C 02 0E 37 00 00
  5.4a  absolute 2 turns (65536) 01: FF 06 16 02 00 00 01 00 -> FF: 01 06 16 02 0E 37 00 00
  5.4a  absolute 1 (origin)      01: FF 06 16 02 01 00 00 00 -> FF: 01 06 16 02 11 37 00 00
  5.4b  steps (1)-(3) repeat the 5.4a speed and absolute frames byte for byte
  5.5   error reply              FF: 01 90 00
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError, FramingError
from servobus.families.yzaim import registers as yzaim
from servobus.protocols.easycan import codec
from servobus.protocols.easycan import describe as D
from servobus.protocols.easycan import messages as M
from servobus.protocols.easycan.functions import HOST_ADDRESS, SPECS, ErrorCode, Function


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# (request, request frame, reply, reply frame); reply None: the drive does not answer
GOLDEN: list[tuple[str, M.Request, tuple[int, str], M.Reply | None, tuple[int, str]]] = [
    ("5.3a read 1", M.ReadRequest(1, 0x00, 1), (0x01, "FF 03 00 01"),
     M.ReadReply(1, 0x00, (0,)), (0xFF, "01 03 00 01 00 00")),
    ("5.3a read 2", M.ReadRequest(1, 0x00, 2), (0x01, "FF 03 00 02"),
     M.ReadReply(1, 0x00, (0, 1)), (0xFF, "01 03 00 02 00 00 01 00")),
    ("5.3b write 1", M.WriteRequest(1, 0x00, (1,)), (0x01, "FF 06 00 01 01 00"),
     M.WriteReply(1, 0x00, (1,)), (0xFF, "01 06 00 01 01 00")),
    ("5.3b write 2", M.WriteRequest(1, 0x00, (1, 1)), (0x01, "FF 06 00 02 01 00 01 00"),
     M.WriteReply(1, 0x00, (1, 1)), (0xFF, "01 06 00 02 01 00 01 00")),
    ("5.3c cache silent", M.PositionCacheWrite(1, 0), (0x101, "00 00 00 00"), None, (0, "")),
    ("5.3c cache reply", M.PositionCacheWrite(1, 0, reply=True), (0x301, "00 00 00 00"),
     M.PositionReply(0), (0xFF, "00 00 00 00")),
    ("5.3d emergency stop", M.EmergencyStop(1), (0x01, "FF 10"),
     M.EmergencyStopReply(1), (0xFF, "01 10")),
    ("5.3e clear position", M.ClearPosition(1), (0x01, "FF 11 00 00"), None, (0, "")),
    ("5.3f read three", M.ReadMultipleRequest(1, (0x00, 0x01, 0x02)), (0x01, "FF 12 00 01 02"),
     M.ReadMultipleReply(1, (1, 1, 1)), (0xFF, "01 12 01 00 01 00 01 00")),
    ("5.4a special function 0", M.WriteRequest(1, 0x19, (0,)), (0x01, "FF 06 19 01 00 00"),
     M.WriteReply(1, 0x19, (0,)), (0xFF, "01 06 19 01 00 00")),
    ("5.4a save", M.WriteRequest(1, 0x14, (1,)), (0x01, "FF 06 14 01 01 00"),
     M.WriteReply(1, 0x14, (1,)), (0xFF, "01 06 14 01 01 00")),
    ("5.4a speed+accel", M.WriteRequest(1, 0x02, (1000, 10000)),
     (0x01, "FF 06 02 02 E8 03 10 27"),
     M.WriteReply(1, 0x02, (1000, 10000)), (0xFF, "01 06 02 02 E8 03 10 27")),
    ("5.4a incremental +32768", M.WriteRequest(1, 0x0C, yzaim.split32(32768)),
     (0x01, "FF 06 0C 02 00 80 00 00"),
     M.WriteReply(1, 0x0C, (0x370E, 0)), (0xFF, "01 06 0C 02 0E 37 00 00")),
    ("5.4a incremental -32768", M.WriteRequest(1, 0x0C, yzaim.split32(-32768)),
     (0x01, "FF 06 0C 02 00 80 FF FF"),
     M.WriteReply(1, 0x0C, (0x370E, 0)), (0xFF, "01 06 0C 02 0E 37 00 00")),
    ("5.4a absolute 2 turns", M.WriteRequest(1, 0x16, yzaim.split32(65536)),
     (0x01, "FF 06 16 02 00 00 01 00"),
     M.WriteReply(1, 0x16, (0x370E, 0)), (0xFF, "01 06 16 02 0E 37 00 00")),
    ("5.4a absolute 1", M.WriteRequest(1, 0x16, yzaim.split32(1)),
     (0x01, "FF 06 16 02 01 00 00 00"),
     M.WriteReply(1, 0x16, (0x3711, 0)), (0xFF, "01 06 16 02 11 37 00 00")),
]


@pytest.mark.parametrize("case", GOLDEN, ids=[g[0] for g in GOLDEN])
def test_golden_frames(case: tuple[str, M.Request, tuple[int, str], M.Reply | None,
                                   tuple[int, str]]) -> None:
    _, req, (req_id, req_hex), rep, (rep_id, rep_hex) = case
    assert codec.encode(req) == (req_id, h(req_hex))
    assert codec.decode_request(req_id, h(req_hex)) == req
    assert codec.decode(req_id, h(req_hex)) == req
    assert codec.expects_reply(req) == (rep is not None)
    if rep is None:
        return
    assert codec.encode(rep) == (rep_id, h(rep_hex))
    decoded = codec.decode_reply(rep_id, h(rep_hex), codec.reply_is_position(req))
    assert decoded == rep
    assert codec.answers(req, decoded)


def test_golden_positions() -> None:
    """The values the manual's prose gives for the example frames."""
    w = codec.decode_request(1, h("FF 06 0C 02 00 80 FF FF"))
    assert isinstance(w, M.WriteRequest) and w.values == (0x8000, 0xFFFF)
    assert yzaim.join32(*w.values) == -32768
    w = codec.decode_request(1, h("FF 06 16 02 00 00 01 00"))
    assert isinstance(w, M.WriteRequest) and yzaim.join32(*w.values) == 65536  # 2 turns
    r = codec.decode_reply(0xFF, h("01 06 0C 02 0E 37 00 00"))
    assert isinstance(r, M.WriteReply) and r.position == 0x370E
    r = codec.decode_reply(0xFF, h("01 06 16 02 11 37 00 00"))
    assert isinstance(r, M.WriteReply) and r.position == 0x3711
    assert M.WriteReply(1, 0x02, (1000, 10000)).position is None


def test_golden_error_reply() -> None:
    err = codec.decode_reply(0xFF, h("01 90 00"))
    assert err == M.ErrorReply(1, Function.EMERGENCY_STOP, 0)
    assert codec.encode(err) == (0xFF, h("01 90 00"))
    assert codec.answers(M.EmergencyStop(1), err)
    assert "unknown error code 0x00" in D.describe(err)


def test_clear_position_short_form_accepted() -> None:
    assert codec.decode_request(1, h("FF 11")) == M.ClearPosition(1)
    assert codec.decode_request(1, h("FF 11 00")) == M.ClearPosition(1)


def test_one_register_multi_read_needs_context() -> None:
    frame = h("01 12 34 12")
    assert codec.decode_reply(0xFF, frame) == M.PositionReply(0x12341201)
    req = M.ReadMultipleRequest(1, (0x16,))
    rep = codec.decode_reply(0xFF, frame, codec.reply_is_position(req))
    assert rep == M.ReadMultipleReply(1, (0x1234,))
    assert codec.answers(req, rep)
    assert "absolute_position_low = 4660" in D.describe_frame(0xFF, frame, after=req)


# ------------------------------------------------------------------ describe


@pytest.mark.parametrize(("frame", "text"), [
    ((0x01, "FF 03 16 02"), "host -> 1: READ absolute_position"),
    ((0x01, "FF 06 02 02 E8 03 10 27"),
     "host -> 1: WRITE target_speed = 1000 rpm, acceleration = 10000 rpm/s"),
    ((0x01, "FF 06 0C 02 00 80 FF FF"), "host -> 1: WRITE incremental_position = -32768"),
    ((0xFF, "01 06 0C 02 0E 37 00 00"), "absolute position 14094"),
    ((0xFF, "01 03 10 01 98 3A"), "motor_speed = 15000 (1500 rpm)"),
    ((0xFF, "01 03 10 01 68 C5"), "motor_speed = -15000 (-1500 rpm)"),
    ((0xFF, "01 03 0F 01 D0 07"), "system_current = 2000 (1 A)"),
    ((0x01, "FF 12 0E 10 11"), "READ_MULTIPLE alarm_code, motor_speed, supply_voltage"),
    ((0x101, "00 80 00 00"), "POSITION_CACHE 32768 (no reply)"),
    ((0x301, "00 80 FF FF"), "POSITION_CACHE -32768 (reply with position)"),
    ((0x01, "FF 10"), "host -> 1: EMERGENCY_STOP"),
    ((0xFF, "01 10"), "EMERGENCY_STOP done"),
    ((0x01, "FF 11 00 00"), "CLEAR_POSITION (no reply)"),
    ((0xFF, "02 83 02"), "2 -> host: ERROR on READ: 0x02 illegal register address"),
    ((0x01, "FF 03 40 01"), "READ register 0x40"),
    ((0x201, "00"), "malformed"),
    ((0x01, "FF 06 00 01"), "malformed"),
])
def test_describe(frame: tuple[int, str], text: str) -> None:
    assert text in D.describe_frame(frame[0], h(frame[1]))


# ------------------------------------------------------------------ malformed frames


@pytest.mark.parametrize(("frame", "code"), [
    ((0x01, "FF 42"), ErrorCode.ILLEGAL_FUNCTION),
    ((0x01, "FF 03 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 03 00 01 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 06 00 01 01"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 06 00 02 01 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 06 00 01 01 00 01 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 06 00 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 10 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 11 00 00 00"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 12"), ErrorCode.ILLEGAL_DATA_LENGTH),
    ((0x01, "FF 12 00 01 02 03"), ErrorCode.ILLEGAL_DATA_LENGTH),
])
def test_malformed_request_names_the_error_reply(frame: tuple[int, str],
                                                 code: ErrorCode) -> None:
    with pytest.raises(codec.MalformedRequest) as info:
        codec.decode_request(frame[0], h(frame[1]))
    assert isinstance(info.value, FramingError)
    err = info.value.error_reply()
    assert (err.slave, err.host, err.code) == (1, 0xFF, code)
    assert err.function == h(frame[1])[1]


@pytest.mark.parametrize(("ident", "data"), [
    (0x800, ""), (-1, ""), (0x01, "FF 03 00 01 00 00 00 00 00"), (0x01, ""), (0x01, "FF"),
    (0x201, "00 00 00 00"), (0x401, "00 00 00 00"), (0x101, "00 00 00"), (0x301, ""),
    (0x1FF, "00 00 00 00"),
])
def test_malformed_requests(ident: int, data: str) -> None:
    with pytest.raises(FramingError):
        codec.decode_request(ident, h(data))


@pytest.mark.parametrize("data", [
    "", "01", "01 90", "01 90 00 00 00", "FF 03 00 01 00 00", "01 42 00", "01 11 00 00 00",
    "01 03 00 02 00 00", "01 03 00 01 00 00 01 00", "01 06 00 01 00", "01 10 00",
    "01 12 00", "01 03 00 01 00 00 00 00 00",
])
def test_malformed_replies(data: str) -> None:
    with pytest.raises(FramingError):
        codec.decode_reply(0xFF, h(data), position=False)


def test_malformed_reply_shapes() -> None:
    with pytest.raises(FramingError):
        codec.decode_reply(0xFF, h("00 00 00"), position=True)
    with pytest.raises(FramingError):
        codec.decode_reply(0x1FF, h("00 00 00 00"))
    with pytest.raises(FramingError):
        codec.decode_request(0xFF, h("01 03 00 01 00 00"))  # the host's id is not a request


def test_structural_checks_on_construction() -> None:
    for make in (
        lambda: M.ReadRequest(0xFF, 0),
        lambda: M.ReadRequest(1, 0x100),
        lambda: M.WriteRequest(1, 0, ()),
        lambda: M.WriteRequest(1, 0, (1, 2, 3)),
        lambda: M.WriteRequest(1, 0, (0x10000,)),
        lambda: M.WriteRequest(1, 0, (-1,)),
        lambda: M.ReadMultipleRequest(1, ()),
        lambda: M.ReadMultipleRequest(1, (1, 2, 3, 4)),
        lambda: M.PositionCacheWrite(1, 2**31),
        lambda: M.PositionReply(-(2**31) - 1),
        lambda: M.ErrorReply(1, 0x80, 2),
        lambda: M.ReadReply(1, 0, (1, 2, 3)),
        lambda: M.ReadMultipleReply(1, (1, 2, 3, 4)),
        lambda: M.EmergencyStop(True),
    ):
        with pytest.raises(ArgumentRangeError):
            make()


@given(st.integers(-10, 0x810), st.binary(max_size=10), st.sampled_from([None, True, False]))
def test_any_frame_decodes_or_raises_framing_error(ident: int, data: bytes,
                                                   position: bool | None) -> None:
    try:
        msg = codec.decode(ident, data, position)
    except FramingError:
        return
    again_id, again = codec.encode(msg)
    assert again_id == ident
    if isinstance(msg, M.ClearPosition):
        assert again[:2] == data[:2]  # padding bytes are not kept
    else:
        assert again == data


# ------------------------------------------------------------------ properties

slaves = st.integers(0, 0xFE)
hosts = st.integers(0, 0xFF)
addresses = st.integers(0, 0xFF)
words = st.integers(0, 0xFFFF)
int32 = st.integers(-(2**31), 2**31 - 1)
few_words = st.lists(words, min_size=1, max_size=2).map(tuple)

requests = st.one_of(
    st.builds(M.ReadRequest, slaves, addresses, st.integers(0, 0xFF), hosts),
    st.builds(M.WriteRequest, slaves, addresses, few_words, hosts),
    st.builds(M.EmergencyStop, slaves, hosts),
    st.builds(M.ClearPosition, slaves, hosts),
    st.builds(M.ReadMultipleRequest, slaves,
              st.lists(addresses, min_size=1, max_size=3).map(tuple), hosts),
    st.builds(M.PositionCacheWrite, slaves, int32, st.booleans()),
)
replies = st.one_of(
    st.builds(M.ReadReply, slaves, addresses, few_words, hosts),
    st.builds(M.WriteReply, slaves, addresses, few_words, hosts),
    st.builds(M.EmergencyStopReply, slaves, hosts),
    st.builds(M.ReadMultipleReply, slaves, st.lists(words, min_size=2, max_size=3).map(tuple),
              hosts),
    st.builds(M.PositionReply, int32, hosts),
    st.builds(M.ErrorReply, slaves, st.integers(0, 0x7F), st.integers(0, 0xFF), hosts),
)


@given(requests)
def test_request_roundtrip(req: M.Request) -> None:
    ident, data = codec.encode(req)
    assert 0 <= ident <= 0x7FF and len(data) <= 8
    assert codec.decode_request(ident, data) == req
    if not isinstance(req, M.PositionCacheWrite):
        assert len(data) in SPECS[req.function].request_lengths


@given(replies)
def test_reply_roundtrip(rep: M.Reply) -> None:
    ident, data = codec.encode(rep)
    assert ident == rep.host and len(data) <= 8
    assert codec.decode_reply(ident, data, isinstance(rep, M.PositionReply)) == rep


@given(st.builds(M.ReadMultipleReply, slaves, st.tuples(words), hosts))
def test_one_register_multi_read_roundtrip(rep: M.ReadMultipleReply) -> None:
    assert codec.decode_reply(*codec.encode(rep), position=False) == rep


@given(requests)
def test_sniff_roundtrip_and_describe(req: M.Request) -> None:
    ident, data = codec.encode(req)
    if ident != HOST_ADDRESS:
        assert codec.decode(ident, data) == req
    assert "malformed" not in D.describe(req)


@given(replies)
def test_describe_never_raises(rep: M.Reply) -> None:
    assert D.describe(rep)


@given(slaves, int32)
def test_position_cache_is_signed_little_endian(slave: int, position: int) -> None:
    ident, data = codec.encode(M.PositionCacheWrite(slave, position, reply=True))
    assert ident == 0x300 | slave
    assert data == position.to_bytes(4, "little", signed=True)
    low, high = yzaim.split32(position)
    assert data == low.to_bytes(2, "little") + high.to_bytes(2, "little")


def test_answers_rejects_mismatches() -> None:
    req = M.ReadRequest(1, 0x16, 2)
    assert codec.answers(req, M.ReadReply(1, 0x16, (0, 0)))
    assert not codec.answers(req, M.ReadReply(2, 0x16, (0, 0)))
    assert not codec.answers(req, M.ReadReply(1, 0x17, (0, 0)))
    assert not codec.answers(req, M.ReadReply(1, 0x16, (0,)))
    assert not codec.answers(req, M.WriteReply(1, 0x16, (0, 0)))
    assert not codec.answers(req, M.ErrorReply(1, Function.WRITE, 2))
    assert codec.answers(req, M.ErrorReply(1, Function.READ, 2))
    assert not codec.answers(req, M.PositionReply(0))
    assert not codec.answers(M.PositionCacheWrite(1, 0), M.PositionReply(0))
    assert codec.answers(M.PositionCacheWrite(1, 0, True), M.PositionReply(0))
    assert not codec.answers(M.ReadMultipleRequest(1, (1, 2)), M.ReadMultipleReply(1, (1, 2, 3)))
    assert not codec.answers(M.ReadRequest(1, 0, host=0x7F), M.ReadReply(1, 0, (0,)))
