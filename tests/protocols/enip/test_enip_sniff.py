"""``servobus decode --protocol enip``: encapsulation packets from a TCP byte stream, with the
DYN5 meaning of Parameter instances; any chunking, any garbage, never an exception."""

from __future__ import annotations

import struct
import subprocess
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.protocols.enip.codec import cpf
from servobus.protocols.enip.codec.encap import EncapPacket
from servobus.protocols.enip.sniff import DECODER, EnipEvent
from servobus.sniff import decode_stream, decoders


def rr(message: bytes, context: bytes = b"servobus") -> bytes:
    return EncapPacket(0x6F, cpf.plain_rr_data(message), 0x1234, context=context).encode()


SPEED_500 = rr(bytes((0x10, 3, 0x20, 0x0F, 0x24, 0x0E, 0x30, 1)) + struct.pack("<i", 500))
GET_POSITION = rr(bytes((0x0E, 3, 0x20, 0x0F, 0x24, 0x1D, 0x30, 1)), b"ask-pos!")
POSITION_REPLY = rr(bytes((0x8E, 0, 0, 0)) + struct.pack("<i", 2_895_232), b"ask-pos!")
REFUSED = rr(bytes((0x90, 0, 0x05, 0)))
CAPTURE = SPEED_500 + GET_POSITION + POSITION_REPLY + REFUSED


def texts(data: bytes, chunk: int | None = None) -> list[str]:
    chunks = [data] if chunk is None else [data[i:i + chunk] for i in range(0, len(data), chunk)]
    return [e.lines()[0] for e in decode_stream(DECODER, chunks)]


def test_registered_as_a_byte_decoder() -> None:
    assert decoders()["enip"].medium == "bytes"


def test_requests_and_replies_in_dyn5_terms() -> None:
    lines = texts(CAPTURE)
    assert "SET_ATTRIBUTE_SINGLE class 0x0F instance 0x0E turn_const_speed attribute 1 = 500" \
        in lines[0]  # manual 6.2: a speed command
    assert "GET_ATTRIBUTE_SINGLE class 0x0F instance 0x1D motor_position" in lines[1]
    assert "reply GET_ATTRIBUTE_SINGLE 0x1D motor_position: = 2895232" in lines[2]  # 6.3 value
    assert "DYN5 error 05" in lines[3]


def test_any_chunking_gives_the_same_lines() -> None:
    whole = texts(CAPTURE)
    for chunk in (1, 5, 24, 25):
        assert texts(CAPTURE, chunk) == whole


@given(st.binary(max_size=200))
def test_garbage_never_raises(data: bytes) -> None:
    for event in decode_stream(DECODER, [data]):
        assert event.is_error or isinstance(event, EnipEvent)


@pytest.mark.slow  # a real process
def test_cli_decode_with_protocol_enip() -> None:
    done = subprocess.run([sys.executable, "-m", "servobus", "decode", "--protocol", "enip",
                           SPEED_500.hex()], capture_output=True, text=True, timeout=30,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert "turn_const_speed attribute 1 = 500" in done.stdout
