"""DYN5 Class 1 images and frames (manual section 5 and the 6.3 I/O example)."""

from __future__ import annotations

import contextlib

import enip_raw as raw
import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import FramingError, ProtocolError
from servobus.protocols.enip.codec import io
from servobus.protocols.enip.codec.io import InputImage, IoFrame, OutputImage

_i32 = st.integers(-(1 << 31), (1 << 31) - 1)


def test_manual_6_3_input_example() -> None:
    # input1 = 2895232, 501, 60, 0: absolute position, 501 rpm CW, torque 60, status normal
    image = InputImage(2_895_232, 501, 60, 0)
    assert image.encode() == bytes.fromhex("802d2c00 f5010000 3c000000 00000000")
    assert InputImage.decode(image.encode()) == image
    frame = io.input_frame(0x7000_0001, 1, 1, image)
    assert raw.parse_io(frame, 0.0).values == (2_895_232, 501, 60, 0)


def test_manual_6_3_output_words() -> None:
    assert OutputImage(57054).encode() == bytes.fromhex("01000000 dede0000")
    assert OutputImage(43690).encode() == bytes.fromhex("01000000 aaaa0000")
    assert OutputImage(43690).enable is True and OutputImage(57054).enable is False
    assert OutputImage(0).enable is None  # the example's output1 = 0: no command
    assert OutputImage.decode(bytes.fromhex("00000000 aaaa0000")) == OutputImage(43690, False)


def test_connection_sizes_of_notes() -> None:
    assert (io.O_T_CONNECTION_SIZE, io.T_O_CONNECTION_SIZE) == (10, 18)


def test_frame_layout_matches_the_spec() -> None:
    frame = io.output_frame(0x01020304, 7, 3, OutputImage(0xAAAA))
    assert frame == raw.output_datagram(0x01020304, 7, 3, 0xAAAA)
    assert frame == bytes.fromhex("0200 0280 0800 04030201 07000000 b100 0a00 0300 01000000"
                                  " aaaa0000")
    assert IoFrame.decode(frame) == IoFrame(0x01020304, 7, 3, OutputImage(0xAAAA).encode())


@given(_i32, _i32, _i32, st.integers(0, 0xFFFF_FFFF))
def test_input_image_round_trip(p: int, s: int, t: int, status: int) -> None:
    image = InputImage(p, s, t, status)
    assert InputImage.decode(image.encode()) == image


@given(st.integers(0, 0xFFFF_FFFF), st.booleans())
def test_output_image_round_trip(word: int, run: bool) -> None:
    assert OutputImage.decode(OutputImage(word, run).encode()) == OutputImage(word, run)


@given(st.integers(0, 0xFFFF_FFFF), st.integers(0, 0xFFFF_FFFF), st.integers(0, 0xFFFF),
       st.binary(max_size=32))
def test_frame_round_trip(cid: int, seq: int, count: int, payload: bytes) -> None:
    frame = IoFrame(cid, seq, count, payload)
    assert IoFrame.decode(frame.encode()) == frame


@given(st.binary(max_size=48))
def test_frame_decoder_raises_only_typed_errors(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        IoFrame.decode(data)


def test_bad_frames() -> None:
    with pytest.raises(FramingError):
        IoFrame.decode(bytes.fromhex("0100 0280 0800 0000000000000000"))
    with pytest.raises(FramingError):
        InputImage(1 << 31, 0, 0, 0).encode()
    with pytest.raises(FramingError):
        InputImage.decode(bytes(15))


@given(st.integers(0, 0xFFFF_FFFF), st.integers(1, 0x7FFF_FFFF))
def test_seq32_order_wraps(last: int, step: int) -> None:
    assert io.seq32_newer((last + step) & 0xFFFF_FFFF, last)
    assert not io.seq32_newer(last, (last + step) & 0xFFFF_FFFF)
    assert not io.seq32_newer(last, last)


def test_seq16_order_wraps() -> None:
    assert io.seq16_newer(0, 0xFFFF) and not io.seq16_newer(0xFFFF, 0)
    assert not io.seq16_newer(5, 5)
