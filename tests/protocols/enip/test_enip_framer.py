"""The encapsulation stream framer: random chunking, oversize packets, garbage."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.protocols.enip.codec.encap import (
    HEADER_SIZE,
    EncapFramer,
    EncapPacket,
    EncapReject,
    EncapStatus,
)

_packets = st.builds(EncapPacket, st.integers(0, 0xFFFF), st.binary(max_size=80),
                     st.integers(0, 0xFFFF_FFFF), st.integers(0, 0xFFFF_FFFF),
                     st.binary(min_size=8, max_size=8), st.integers(0, 0xFFFF_FFFF))


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


@given(st.lists(_packets, max_size=8), st.lists(st.integers(0, 10_000), max_size=20))
def test_random_chunking_gives_the_same_packets(packets: list[EncapPacket],
                                                cuts: list[int]) -> None:
    stream = b"".join(p.encode() for p in packets)
    framer = EncapFramer(max_data=100)
    out: list[EncapPacket | EncapReject] = []
    for chunk in chunked(stream, cuts):
        out += framer.feed(chunk)
    assert out == packets
    assert framer.buffered == 0


@given(st.lists(st.integers(0, 10_000), max_size=20), st.integers(101, 3000))
def test_oversize_packet_is_rejected_skipped_and_never_buffered(cuts: list[int],
                                                                size: int) -> None:
    big = EncapPacket(0x6F, bytes(size), 7, 0, b"ctx12345")
    small = EncapPacket(0x63, b"", 0, 0, b"after!!!")
    framer = EncapFramer(max_data=100)
    out: list[EncapPacket | EncapReject] = []
    for chunk in chunked(big.encode() + small.encode(), cuts):
        out += framer.feed(chunk)
        assert framer.buffered < HEADER_SIZE + 100
    assert len(out) == 2
    reject = out[0]
    assert isinstance(reject, EncapReject)
    assert reject.status is EncapStatus.INVALID_LENGTH and reject.header.context == b"ctx12345"
    assert out[1] == small


@settings(max_examples=300)
@given(st.lists(st.binary(max_size=200), max_size=30))
def test_garbage_never_raises_and_stays_bounded(chunks: list[bytes]) -> None:
    framer = EncapFramer(max_data=64)
    for chunk in chunks:
        for item in framer.feed(chunk):
            assert isinstance(item, EncapPacket | EncapReject)
        assert framer.buffered < HEADER_SIZE + 64


def test_packet_split_inside_the_header() -> None:
    pkt = EncapPacket(0x65, b"\x01\x00\x00\x00", 0, 0, b"abcdefgh")
    raw = pkt.encode()
    framer = EncapFramer()
    assert framer.feed(raw[:5]) == [] and framer.feed(raw[5:27]) == []
    assert framer.feed(raw[27:] + raw) == [pkt, pkt]
