"""DYN232M codec: the manual's worked examples byte for byte, boundaries, properties."""

from __future__ import annotations

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError, ChecksumError, FramingError
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c

H = c.HostFunction

# (drive id, function, value, bytes) from section 7.6 examples 1-6 and 7.2.6
GOLDEN = [
    (3, DmmFunction.SET_ORIGIN, 0, "03 80 80 83"),  # example 1
    (3, DmmFunction.GO_ABSOLUTE_POS, 0, "03 81 80 84"),  # example 2
    (3, DmmFunction.GO_RELATIVE_POS, 120, "03 a3 80 f8 9e"),  # example 3
    (3, DmmFunction.GO_RELATIVE_POS, -120, "03 a3 ff 88 ad"),  # example 4
    (2, DmmFunction.TURN_CONST_SPEED, 60, "02 8a bc c8"),  # example 5
    (2, DmmFunction.TURN_CONST_SPEED, -60, "02 8a c4 d0"),  # example 6
    (8, DmmFunction.TURN_CONST_SPEED, 50, "08 8a b2 c4"),  # 7.2.6 checksum example
]


@pytest.mark.parametrize(("drive_id", "fn", "value", "hexbytes"), GOLDEN)
def test_worked_examples_encode(drive_id: int, fn: int, value: int, hexbytes: str) -> None:
    assert c.encode(drive_id, fn, value) == bytes.fromhex(hexbytes)


@pytest.mark.parametrize(("drive_id", "fn", "value", "hexbytes"), GOLDEN)
def test_worked_examples_decode(drive_id: int, fn: int, value: int, hexbytes: str) -> None:
    p = c.decode(bytes.fromhex(hexbytes))
    assert (p.drive_id, p.function, p.value) == (drive_id, fn, value)


def test_const_speed_742_erratum() -> None:
    # 7.4.2 writes 1400 = 0x578 as B2 = 1000 0101, B1 = 1111 1000: that splits the hex
    # digits, not 7-bit groups, and would decode to 760. The 7-bit grouping of examples 1-6,
    # Send_Package and Cal_SignValue gives B2 = 0x8a. The -120 example there is right.
    assert c.encode(0, DmmFunction.TURN_CONST_SPEED, 1400)[2:4] == bytes([0x8A, 0xF8])
    assert c.Packet(0, DmmFunction.TURN_CONST_SPEED, bytes([0x05, 0x78])).value == 760
    assert c.encode(0, DmmFunction.TURN_CONST_SPEED, -120)[2:4] == bytes([0b11111111, 0b10001000])


def test_checksum_rule_from_notes() -> None:
    raw = bytes.fromhex("08 8a b2 c4")
    assert (sum(raw[:-1]) ^ raw[-1]) & 0x7F == 0
    assert c.checksum(raw[:-1]) == 0xC4


@pytest.mark.parametrize(
    ("value", "n"),
    [
        (-64, 1), (63, 1), (64, 2), (-65, 2),
        (-8192, 2), (8191, 2), (8192, 3), (-8193, 3),
        (-1_048_576, 3), (1_048_575, 3), (1_048_576, 4), (-1_048_577, 4),
        (-134_217_728, 4), (134_217_727, 4),
    ],
)
def test_boundaries_use_fewest_bytes(value: int, n: int) -> None:
    raw = c.encode(1, DmmFunction.GO_ABSOLUTE_POS, value)
    assert len(raw) == n + 3
    assert (raw[1] >> 5) & 3 == n - 1
    assert c.decode(raw).value == value


@pytest.mark.parametrize("value", [134_217_728, -134_217_729, 1 << 40])
def test_out_of_28_bit_range_is_refused(value: int) -> None:
    with pytest.raises(ArgumentRangeError):
        c.encode(1, DmmFunction.GO_ABSOLUTE_POS, value)


def test_gear_16384_needs_three_bytes() -> None:
    raw = c.encode(1, H.SET_GEAR_NUMBER, 16384)
    assert len(raw) == 6 and c.decode(raw).value == 16384


def test_one_byte_parameter_reply_is_unsigned() -> None:
    raw = c.encode_reply(1, c.DriveFunction.IS_MAIN_GAIN, 100)
    assert len(raw) == 4
    p = c.decode(raw)
    assert p.reply_value() == 100 and p.value == 100 - 128
    status = c.decode(c.encode_reply(1, c.DriveFunction.IS_STATUS, 0x61))
    assert status.reply_value() == 0x61


def test_position_reply_is_signed() -> None:
    raw = c.encode_reply(5, c.DriveFunction.IS_ABS_POS32, -560_000)
    assert c.decode(raw).reply_value() == -560_000


def test_bad_checksum_raises_and_keeps_raw() -> None:
    raw = bytearray(bytes.fromhex("03 a3 80 f8 9e"))
    raw[-1] ^= 0x01
    with pytest.raises(ChecksumError) as info:
        c.decode(raw)
    assert info.value.raw == bytes(raw)


@pytest.mark.parametrize("hexbytes", ["03 80 80", "83 80 80 83", "03 a0 80 83", "03 80 00 83"])
def test_malformed_packets(hexbytes: str) -> None:
    with pytest.raises(FramingError):
        c.decode(bytes.fromhex(hexbytes))


def test_reply_functions() -> None:
    assert c.reply_function(H.READ_MAIN_GAIN) is c.DriveFunction.IS_MAIN_GAIN
    assert c.reply_function(H.READ_GEAR_NUMBER) is c.DriveFunction.IS_GEAR_NUMBER
    assert c.reply_function(DmmFunction.READ_DRIVE_ID) is c.DriveFunction.IS_DRIVE_ID
    assert c.reply_function(DmmFunction.GENERAL_READ, 0x1B) is c.DriveFunction.IS_ABS_POS32
    assert c.reply_function(DmmFunction.GENERAL_READ, 0x1D) is c.DriveFunction.IS_SPEED
    assert c.reply_function(DmmFunction.GENERAL_READ, 0x1E) is c.DriveFunction.IS_TRQ_CURRENT
    for silent in (0x1C, 0x20, 0x21, 0x00):
        assert c.reply_function(DmmFunction.GENERAL_READ, silent) is None
    assert c.reply_function(DmmFunction.GO_ABSOLUTE_POS) is None
    assert c.PARAM_FUNCTIONS["gear_num"] == (H.SET_GEAR_NUMBER, H.READ_GEAR_NUMBER)
    assert len(c.PARAM_FUNCTIONS) == 8


def test_framer_any_chunking_and_resync() -> None:
    stream = (
        bytes.fromhex("03 a3 80")  # truncated by the next start byte
        + bytes.fromhex("03 a3 ff 88 ad")
        + b"\xff\xfe"  # stray bytes
        + bytes.fromhex("02 8a c4 d1")  # bad checksum
        + bytes.fromhex("02 8a c4 d0")
    )
    for chunk in (1, 2, 3, 7, len(stream)):
        f = c.Framer()
        events = []
        for i in range(0, len(stream), chunk):
            events += f.feed(stream[i : i + chunk])
        packets = [e for e in events if isinstance(e, c.Packet)]
        errors = [e for e in events if not isinstance(e, c.Packet)]
        assert [p.value for p in packets] == [-120, -60]
        kinds = [type(e) for e in errors]
        assert kinds == [FramingError, FramingError, ChecksumError]


@given(st.integers(c.VALUE_MIN, c.VALUE_MAX), st.integers(0, 127), st.integers(0, 31))
def test_round_trip_every_value(value: int, drive_id: int, fn: int) -> None:
    p = c.decode(c.encode(drive_id, fn, value))
    assert (p.drive_id, p.function, p.value) == (drive_id, fn, value)


packet_st = st.builds(
    lambda i, f, v: c.encode(i, f, v),
    st.integers(0, 127), st.integers(0, 31), st.integers(c.VALUE_MIN, c.VALUE_MAX),
)


@given(st.lists(st.tuples(packet_st, st.binary(max_size=12)), max_size=20), st.integers(1, 9))
def test_garbage_between_packets_never_loses_or_invents(
    items: list[tuple[bytes, bytes]], chunk: int
) -> None:
    for _, garbage in items:
        probe = c.Framer()
        # garbage that by chance forms a whole valid packet is a real packet, not an invention
        assume(not any(isinstance(e, c.Packet) for e in probe.feed(garbage)))
    stream = b"".join(pkt + garbage for pkt, garbage in items)
    f = c.Framer()
    out = []
    for i in range(0, len(stream), chunk):
        out += [e for e in f.feed(stream[i : i + chunk]) if isinstance(e, c.Packet)]
    assert [c.encode_packet(p) for p in out] == [pkt for pkt, _ in items]
