"""Modbus RTU framers and line timing: random chunking, garbage, bad CRC, truncation."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError
from servobus.protocols.modbus.codec import (
    MAX_FRAME,
    MIN_FRAME,
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
    decode_request,
    encode_reply,
    encode_request,
)
from servobus.protocols.modbus.crc import crc_bytes, crc_ok, good_lengths, with_crc
from servobus.protocols.modbus.framer import GapFramer, ReplyFramer, TimedFrame
from servobus.protocols.modbus.timing import (
    DEFAULT_BAUD,
    char_time_s,
    inter_frame_gap_s,
    wire_time_s,
)

H = bytes.fromhex
Draw = Callable[..., Any]  # st.DrawFn or DataObject.draw
GAP = inter_frame_gap_s(DEFAULT_BAUD)
CHAR = char_time_s(DEFAULT_BAUD)

# ---------------------------------------------------------------------------------- timing


def test_inter_frame_gap() -> None:
    assert pytest.approx(3.5 * 10 / 19_200) == GAP  # 8N1 at 19200: 1.823 ms
    assert pytest.approx(1.8229e-3, abs=1e-7) == GAP
    assert inter_frame_gap_s(9_600) == pytest.approx(3.6458e-3, abs=1e-7)
    assert inter_frame_gap_s(19_200, bits_per_char=11) == pytest.approx(2.0052e-3, abs=1e-7)
    assert inter_frame_gap_s(38_400) == 0.00175  # fixed above 19200 (Serial Line 2.5.1.1)
    assert inter_frame_gap_s(115_200) == 0.00175


def test_wire_time() -> None:
    assert wire_time_s(8) == pytest.approx(8 * 10 / 19_200)  # a read request: 4.17 ms
    assert wire_time_s(0) == 0.0
    assert wire_time_s(25, 115_200) == pytest.approx(25 * 10 / 115_200)


@pytest.mark.parametrize("baud", [0, -19_200])
def test_timing_refuses_a_non_positive_baud(baud: int) -> None:
    with pytest.raises(ArgumentRangeError):
        inter_frame_gap_s(baud)
    with pytest.raises(ArgumentRangeError):
        wire_time_s(8, baud)


# ---------------------------------------------------------------------------- strategies

addresses = st.integers(0, 255)
words = st.integers(0, 0xFFFF)
requests: st.SearchStrategy[Request] = st.one_of(
    st.builds(ReadHoldingRequest, st.integers(1, 255), st.integers(0, 0xFF00),
              st.integers(1, 125)),
    st.builds(WriteSingleRequest, st.integers(1, 255), words, words),
    st.builds(WriteMultipleRequest, st.integers(1, 255), st.integers(0, 0xFF00),
              st.lists(words, min_size=1, max_size=123).map(tuple)),
)


def replies_to(request: Request) -> st.SearchStrategy[Reply]:
    exception = st.builds(ExceptionReply, st.just(request.address),
                          st.just(int(request.function)), st.integers(1, 4))
    normal: st.SearchStrategy[Reply]
    match request:
        case ReadHoldingRequest(address=a, count=n):
            normal = st.lists(words, min_size=n, max_size=n).map(
                lambda v: ReadHoldingReply(a, tuple(v)))
        case WriteSingleRequest(address=a, register=r, value=v):
            normal = st.just(WriteSingleReply(a, r, v))
        case WriteMultipleRequest(address=a, start=s, values=v):
            normal = st.just(WriteMultipleReply(a, s, len(v)))
    return st.one_of(normal, exception)


@st.composite
def exchange(draw: st.DrawFn) -> list[bytes]:
    """One request and its reply (or an exception) as they appear on the line."""
    request = draw(requests)
    return [encode_request(request), encode_reply(draw(replies_to(request)))]


def line_frames(draw: Draw, max_exchanges: int = 4) -> list[bytes]:
    pairs = draw(st.lists(exchange(), min_size=1, max_size=max_exchanges))
    return [frame for pair in pairs for frame in pair]


def chunked(draw: Draw, data: bytes) -> list[bytes]:
    """``data`` cut at random points."""
    cuts = sorted(draw(st.sets(st.integers(1, max(1, len(data) - 1)), max_size=6)))
    bounds = [0, *[c for c in cuts if c < len(data)], len(data)]
    return [data[a:b] for a, b in itertools.pairwise(bounds) if b > a]


def paced(chunks: list[bytes], t0: float, silence_before: float = 0.0) -> list[tuple[bytes, float]]:
    """Timestamps of chunks arriving at the line's pace, the first after ``silence_before``."""
    out = []
    t = t0 + silence_before
    for chunk in chunks:
        t += len(chunk) * CHAR
        out.append((chunk, t))
    return out


def feed_all(framer: GapFramer, timed: list[tuple[bytes, float]]) -> list[bytes]:
    got = [f.raw for chunk, t in timed for f in framer.feed(chunk, t)]
    return got + [f.raw for f in framer.flush()]


def contains_frame(data: bytes, starts: int | None = None) -> bool:
    """True when a slice of ``data`` of 4 bytes or more, starting before ``starts``, passes
    the CRC."""
    return any(good_lengths(data, i, 4, len(data)) for i in range(starts or len(data)))


# -------------------------------------------------------------------------- GapFramer


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_gap_framer_random_chunking_with_silences(data: st.DataObject) -> None:
    frames = line_frames(data.draw)
    framer = GapFramer()
    timed: list[tuple[bytes, float]] = []
    t = 10.0
    for frame in frames:
        silence = data.draw(st.floats(GAP * 1.01, GAP * 20))
        timed += paced(chunked(data.draw, frame), t, silence)
        t = timed[-1][1]
    assert feed_all(framer, timed) == frames
    assert (framer.frames, framer.crc_errors, framer.discarded, framer.pending) == \
        (len(frames), 0, 0, 0)


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_gap_framer_frames_back_to_back_without_silence(data: st.DataObject) -> None:
    # a transport that batches bytes (or a host that ignores t3.5): the content splits them
    frames = line_frames(data.draw)
    stream = b"".join(frames)
    framer = GapFramer()
    timed = [(chunk, 1.0) for chunk in chunked(data.draw, stream)]
    assert feed_all(framer, timed) == frames
    assert framer.discarded == 0


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_gap_framer_skips_garbage_between_silences(data: st.DataObject) -> None:
    frames = line_frames(data.draw, 2)
    garbage = data.draw(st.lists(st.binary(min_size=1, max_size=30), min_size=1, max_size=3))
    for g in garbage:
        assume(not contains_frame(g))
    framer = GapFramer()
    timed: list[tuple[bytes, float]] = []
    t = 0.0
    sequence = [*frames]
    for i, g in enumerate(garbage):
        sequence.insert(data.draw(st.integers(0, len(frames) + i)), g)
    for piece in sequence:
        timed += paced(chunked(data.draw, piece), t, 2 * GAP)
        t = timed[-1][1]
    assert feed_all(framer, timed) == frames
    assert framer.discarded == sum(map(len, garbage))
    assert framer.crc_errors == sum(len(g) >= 4 for g in garbage)


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_gap_framer_resynchronises_on_garbage_without_silence(data: st.DataObject) -> None:
    frames = line_frames(data.draw, 2)
    garbage = data.draw(st.binary(min_size=1, max_size=20))
    stream = garbage + b"".join(frames)
    assume(not contains_frame(stream, len(garbage)))
    framer = GapFramer()
    assert feed_all(framer, [(c, 5.0) for c in chunked(data.draw, stream)]) == frames
    assert framer.discarded == len(garbage)


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_gap_framer_drops_and_counts_a_bad_crc_frame(data: st.DataObject) -> None:
    frames = line_frames(data.draw, 2)
    victim = data.draw(st.integers(0, len(frames) - 1))
    bad = bytearray(frames[victim])
    bit = data.draw(st.integers(0, 8 * len(bad) - 1))
    bad[bit // 8] ^= 1 << (bit % 8)
    assume(not contains_frame(bytes(bad)))
    framer = GapFramer()
    timed: list[tuple[bytes, float]] = []
    t = 0.0
    for i, frame in enumerate(frames):
        timed += paced(chunked(data.draw, bytes(bad) if i == victim else frame), t, 2 * GAP)
        t = timed[-1][1]
    assert feed_all(framer, timed) == frames[:victim] + frames[victim + 1:]
    assert framer.crc_errors == 1
    assert framer.discarded == len(bad)


def test_gap_framer_counts_a_bad_crc_frame_followed_at_once_by_a_good_one() -> None:
    bad = H("01 03 00 00 00 0A C5 CE")
    good = H("01 03 00 00 00 01 84 0A")
    framer = GapFramer()
    assert framer.feed(bad + good, 1.0) == []
    assert [f.raw for f in framer.flush()] == [good]
    assert (framer.crc_errors, framer.discarded) == (1, 8)


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_gap_framer_drops_a_truncated_frame(data: st.DataObject) -> None:
    frames = line_frames(data.draw, 2)
    victim = data.draw(st.integers(0, len(frames) - 1))
    cut = frames[victim][:data.draw(st.integers(1, len(frames[victim]) - 1))]
    assume(not contains_frame(cut))
    framer = GapFramer()
    timed: list[tuple[bytes, float]] = []
    t = 0.0
    for i, frame in enumerate(frames):
        timed += paced(chunked(data.draw, cut if i == victim else frame), t, 2 * GAP)
        t = timed[-1][1]
    assert feed_all(framer, timed) == frames[:victim] + frames[victim + 1:]
    assert framer.discarded == len(cut)
    assert framer.crc_errors == (len(cut) >= 4)


def test_gap_framer_waits_for_the_silence_then_times_the_frame() -> None:
    frame = encode_request(ReadHoldingRequest(1, 0x16, 2))
    framer = GapFramer()
    t_end = 1.0 + wire_time_s(len(frame))
    assert framer.feed(frame, t_end) == []
    assert framer.deadline == pytest.approx(t_end + GAP)
    assert framer.flush(t_end + GAP * 0.99) == []
    out = framer.flush(t_end + GAP * 1.01)
    assert [(f.raw, f.time) for f in out] == [(frame, t_end)]
    assert framer.deadline is None
    assert framer.flush() == []


def test_gap_framer_closes_a_frame_when_the_next_chunk_comes_after_the_silence() -> None:
    a = encode_request(WriteSingleRequest(1, 0x19, 0))
    b = encode_reply(WriteSingleReply(1, 0x19, 0))
    framer = GapFramer()
    assert framer.feed(a, 1.0) == []
    out = framer.feed(b, 1.0 + GAP * 1.01 + wire_time_s(len(b)))
    assert [(f.raw, f.time) for f in out] == [(a, 1.0)]
    assert [f.raw for f in framer.flush()] == [b]


def test_gap_framer_splits_at_a_silence_inside_a_frame() -> None:
    # a silence of t3.5 ends a frame (Serial Line 2.5.1.1): both halves are dropped
    frame = encode_request(ReadHoldingRequest(1, 0, 10))
    framer = GapFramer()
    t = 1.0 + wire_time_s(4)
    framer.feed(frame[:4], t)
    assert framer.feed(frame[4:], t + GAP * 1.01 + wire_time_s(4)) == []
    assert framer.flush() == []
    assert (framer.crc_errors, framer.discarded) == (2, 8)


def test_gap_framer_unknown_function_is_delimited_by_silence() -> None:
    frame = with_crc(H("07 2B 0E 01 00"))  # read device identification
    framer = GapFramer(eager=True)
    assert framer.feed(frame, 1.0) == []  # its length is known only at the silence
    out = framer.flush(1.0 + GAP * 1.01)
    assert [f.raw for f in out] == [frame]
    assert decode_request(out[0].raw) == UnsupportedRequest(7, 0x2B, H("0E 01 00"))


def test_gap_framer_prefers_the_frame_the_silence_ends() -> None:
    # a read reply whose first 8 bytes happen to pass the CRC as a read request
    head = H("01 03 06 00 00 00")
    c = crc_bytes(head)
    reply = encode_reply(ReadHoldingReply(1, (0, c[0], c[1] << 8)))
    assert crc_ok(reply[:8])
    framer = GapFramer()
    assert [f.raw for f in framer.feed(reply, 1.0) + framer.flush()] == [reply]
    # an unknown function whose frame holds a shorter one with a good CRC
    inner = with_crc(H("07 2B 0E 01 00"))
    outer = with_crc(inner + H("AA"))
    assert [f.raw for f in framer.feed(outer, 2.0) + framer.flush()] == [outer]
    assert (framer.crc_errors, framer.discarded) == (0, 0)


def _read_request_with_crc_high_byte_zero() -> bytes:
    """A read request of start 0x02xx whose CRC ends in 0x00: its first 7 bytes also pass
    the CRC, as a one-register read reply (byte count 2)."""
    for count in range(1, 126):
        frame = encode_request(ReadHoldingRequest(0x5C, 0x026D, count))
        if frame[-1] == 0:
            return frame
    raise AssertionError("no such count")  # pragma: no cover


def test_gap_framer_two_readings_of_one_run_are_settled_by_what_follows() -> None:
    request = _read_request_with_crc_high_byte_zero()
    assert crc_ok(request[:7]) and crc_ok(request)
    follow = encode_reply(ReadHoldingReply(0x5C, (1, 2)))
    for eager in (False, True):
        framer = GapFramer(eager=eager)
        got = [f.raw for f in framer.feed(request + follow, 1.0) + framer.flush()]
        assert got == [request, follow]
        assert framer.discarded == 0
    # a device's receiver reads request layouts only: no second reading, taken at once
    framer = GapFramer(eager=True, requests_only=True)
    assert framer.feed(request[:7], 1.0) == []
    assert [f.raw for f in framer.feed(request[7:], 1.0)] == [request]


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.lists(requests, min_size=1, max_size=6), st.data())
def test_eager_request_framer_takes_each_request_with_its_last_byte(
        batch: list[Request], data: st.DataObject) -> None:
    framer = GapFramer(eager=True, requests_only=True)
    frames = [encode_request(r) for r in batch]
    got: list[bytes] = []
    for chunk in chunked(data.draw, b"".join(frames)):  # back to back, no silence
        got += [f.raw for f in framer.feed(chunk, 1.0)]
    assert got == frames
    assert (framer.pending, framer.discarded) == (0, 0)


def test_request_framer_drops_replies() -> None:
    framer = GapFramer(requests_only=True)
    replies = [H("01 83 02 C0 F1"), H("11 10 00 01 00 02 12 98"),
               H("11 03 06 AE 41 56 52 43 40 49 AD")]
    t = 0.0
    for reply in replies:
        t += 3 * GAP
        assert framer.feed(reply, t) == []
    assert framer.flush() == []
    assert framer.discarded == sum(map(len, replies))


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.data())
def test_eager_gap_framer_returns_each_frame_with_its_last_byte(data: st.DataObject) -> None:
    frames = line_frames(data.draw)
    # A frame one of whose prefixes also passes the CRC reads as two frames of different
    # lengths: the eager framer waits for the silence then (pinned below), and one cut at
    # the shorter length is the limitation GapFramer's docstring states (a read request at
    # 0x02xx whose CRC ends in 0x00 reads as a one-register reply one byte short; YZ-AIM's
    # registers are 0x00-0x1D). Found by this test: f5 03 02 7d 00 28 c1 00.
    assume(not any(reads_shorter(frame) for frame in frames))
    framer = GapFramer(eager=True)
    t = 0.0
    for frame in frames:
        chunks = chunked(data.draw, frame)
        for k, chunk in enumerate(chunks):
            t += len(chunk) * CHAR
            got = framer.feed(chunk, t)
            if k < len(chunks) - 1:
                assert got == []
            else:
                assert [(f.raw, f.time) for f in got] == [(frame, t)]
        t += 2 * GAP
    assert framer.flush() == []
    assert (framer.crc_errors, framer.discarded) == (0, 0)


def reads_shorter(frame: bytes) -> bool:
    """A proper prefix of ``frame`` (MIN_FRAME bytes or more) passes the CRC."""
    return bool(good_lengths(frame, 0, MIN_FRAME, len(frame) - 1))


def test_eager_gap_framer_waits_for_the_silence_on_a_frame_that_reads_two_ways() -> None:
    frame = H("f5 03 02 7d 00 28 c1 00")  # a read request; its first 7 bytes pass too
    assert crc_ok(frame) and reads_shorter(frame)
    framer = GapFramer(eager=True)
    t = len(frame) * CHAR
    assert framer.feed(frame, t) == []  # two readings: the silence decides
    assert framer.deadline is not None
    assert framer.flush(framer.deadline) == [TimedFrame(frame, t)]  # the one it ends
    assert (framer.crc_errors, framer.discarded) == (0, 0)


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(st.lists(st.tuples(st.binary(min_size=0, max_size=80), st.floats(0, 0.01)),
                max_size=30), st.booleans())
def test_gap_framer_never_raises_and_accounts_for_every_byte(
        chunks: list[tuple[bytes, float]], eager: bool) -> None:
    framer = GapFramer(eager=eager)
    t = 0.0
    delivered = 0
    for chunk, dt in chunks:
        t += dt
        for f in framer.feed(chunk, t):
            assert crc_ok(f.raw)
            delivered += len(f.raw)
        assert framer.pending <= MAX_FRAME
    delivered += sum(len(f.raw) for f in framer.flush())
    assert delivered + framer.discarded == sum(len(c) for c, _ in chunks)
    assert framer.pending == 0


def test_gap_framer_bounds_its_buffer_under_endless_babble() -> None:
    framer = GapFramer()
    noise = bytes(range(256)) * 8
    for i in range(0, len(noise), 64):
        framer.feed(noise[i:i + 64], 1.0)  # no silence ever
        assert framer.pending <= MAX_FRAME
    frame = encode_request(ReadHoldingRequest(1, 0, 1))
    framer.feed(frame, 1.0 + GAP * 1.01 + wire_time_s(len(frame)))
    assert [f.raw for f in framer.flush()] == [frame]


# ------------------------------------------------------------------------- ReplyFramer


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(requests, st.data())
def test_reply_framer_random_chunking(request: Request, data: st.DataObject) -> None:
    reply = data.draw(replies_to(request))
    wire = encode_reply(reply)
    framer = ReplyFramer(request)
    chunks = chunked(data.draw, wire)
    for chunk in chunks[:-1]:
        assert framer.feed(chunk) is None
        assert 1 <= framer.needed <= len(wire)
    assert framer.feed(chunks[-1]) == reply
    assert (framer.crc_errors, framer.discarded, framer.unexpected) == (0, 0, 0)


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(requests, st.data())
def test_reply_framer_skips_garbage_and_bad_crc_before_the_reply(request: Request,
                                                                 data: st.DataObject) -> None:
    reply = data.draw(replies_to(request))
    wire = encode_reply(reply)
    corrupt = bytearray(wire)
    corrupt[data.draw(st.integers(0, len(corrupt) - 1))] ^= data.draw(st.integers(1, 255))
    garbage = data.draw(st.binary(max_size=20))
    stream = garbage + bytes(corrupt) + wire
    framer = ReplyFramer(request)
    got = [framer.feed(c) for c in chunked(data.draw, stream)]
    assert [g for g in got if g is not None] == [reply]
    assert got[-1] == reply


def test_reply_framer_counts_a_bad_crc_reply_and_waits() -> None:
    request = ReadHoldingRequest(1, 0x0E, 1)
    framer = ReplyFramer(request)
    assert framer.feed(H("01 03 02 00 14 B8 4C")) is None
    assert framer.crc_errors == 1
    assert framer.feed(H("01 03 02 00 14 B8 4B")) == ReadHoldingReply(1, (0x14,))


def test_reply_framer_finds_a_reply_that_starts_inside_a_false_start() -> None:
    # "01 06" of noise, then the reply: the first candidate fails its CRC; skipping it whole
    # would lose the reply, so the framer skips one byte at a time
    framer = ReplyFramer(WriteSingleRequest(1, 0x14, 1))
    assert framer.feed(H("01 06 01 06 00 14 00 01 08 0E")) == WriteSingleReply(1, 0x14, 1)
    assert (framer.crc_errors, framer.discarded) == (1, 2)


def test_reply_framer_skips_a_late_reply_to_an_earlier_request() -> None:
    framer = ReplyFramer(WriteSingleRequest(1, 0x14, 1))
    stale = encode_reply(WriteSingleReply(1, 0x19, 0))  # good CRC, another register
    assert framer.feed(stale + H("01 06 00 14 00 01 08")) is None
    assert framer.unexpected == 1
    assert framer.feed(H("0E")) == WriteSingleReply(1, 0x14, 1)


def test_reply_framer_returns_an_exception_reply() -> None:
    framer = ReplyFramer(WriteSingleRequest(1, 0x40, 1))
    assert framer.needed == 5
    assert framer.feed(H("01 86")) is None
    assert framer.needed == 3
    assert framer.feed(H("02 C3 A1")) == ExceptionReply(1, 0x06, 2)


def test_reply_framer_predicts_the_length_of_a_read_reply() -> None:
    framer = ReplyFramer(ReadHoldingRequest(1, 0, 10))
    assert framer.needed == 5
    framer.feed(H("01 03 14"))
    assert framer.needed == 25 - 3
    other = ReplyFramer(ReadHoldingRequest(1, 0, 10))
    other.feed(H("77 01"))  # 0x77 cannot start the reply; 0x01 can
    assert other.needed == 4


def test_reply_framer_rearms_and_discards_leftovers() -> None:
    framer = ReplyFramer(ReadHoldingRequest(1, 0, 1))
    assert framer.feed(H("01 03 02 00 00 B8 44 FF FF")) == ReadHoldingReply(1, (0,))
    assert framer.feed(H("01")) is None  # nothing expected: discarded
    framer.expect(ReadHoldingRequest(1, 0x0E, 1))
    assert framer.discarded == 3
    assert framer.feed(H("01 03 02 00 14 B8 4B")) == ReadHoldingReply(1, (0x14,))


def test_reply_framer_refuses_a_broadcast() -> None:
    with pytest.raises(ArgumentRangeError):
        ReplyFramer(WriteSingleRequest(0, 1, 0))


@pytest.mark.slow  # a property test: seconds of CPU
@settings(deadline=None)
@given(requests, st.lists(st.binary(max_size=40), max_size=10))
def test_reply_framer_never_raises_on_any_bytes(request: Request, chunks: list[bytes]) -> None:
    framer = ReplyFramer(request)
    for chunk in chunks:
        got = framer.feed(chunk)
        if got is not None:
            assert got.address == request.address
            assert got.function == request.function
            break
