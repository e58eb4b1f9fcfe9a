"""The Modbus RTU decoder of decode/sniff: frames cut by content in any chunking, direction,
the write-single echo, errors for garbage and bad CRC; the DECODERS registry entry."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.sniff import DECODER, RtuFrameEvent
from servobus.sniff import BYTES, ErrorEvent, decode_stream, decoder_for

TRAFFIC = [
    C.encode_request(C.ReadHoldingRequest(1, 0x16, 2)),
    C.encode_reply(C.ReadHoldingReply(1, (0x8000, 0))),
    C.encode_request(C.WriteSingleRequest(2, 0x02, 1500)),
    C.encode_reply(C.WriteSingleReply(2, 0x02, 1500)),  # the echo: the same bytes
    C.encode_request(C.WriteMultipleRequest(1, 0x0C, (0x8000, 0))),
    C.encode_reply(C.WriteMultipleReply(1, 0x0C, 2)),
    C.encode_request(C.ReadHoldingRequest(1, 0x1E, 1)),
    C.encode_reply(C.ExceptionReply(1, 0x03, 2)),
]
TEXTS = [
    (False, "id 1 read 0x0016 absolute_position_low x2"),
    (True, "id 1 read reply [32768, 0]"),
    (False, "id 2 write 0x0002 target_speed=1500"),
    (True, "id 2 write 0x0002 target_speed=1500 (echo)"),
    (False, "id 1 write 0x000C incremental_position_low=32768, "
            "0x000D incremental_position_high=0"),
    (True, "id 1 wrote 2 registers from 0x000C incremental_position_low"),
    (False, "id 1 read 0x001E"),
    (True, "id 1 exception ILLEGAL_DATA_ADDRESS to read holding registers: register "
           "address (or address + count) not allowed"),
]


def decode(chunks: list[bytes]) -> list[RtuFrameEvent | ErrorEvent]:
    return list(decode_stream(DECODER, chunks))  # type: ignore[arg-type]


def test_a_conversation_in_one_chunk() -> None:
    events = decode([b"".join(TRAFFIC)])
    assert [(e.from_drive, e.text) for e in events if isinstance(e, RtuFrameEvent)] == TEXTS
    assert all(not e.is_error for e in events)
    assert events[0].as_dict()["direction"] == "host->drive"


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 12), min_size=1, max_size=40))
def test_any_chunking_gives_the_same_frames(sizes: list[int]) -> None:
    data = b"".join(TRAFFIC)
    chunks, i = [], 0
    for size in sizes:
        chunks.append(data[i:i + size])
        i += size
    chunks.append(data[i:])
    events = decode([c for c in chunks if c])
    assert [(e.from_drive, e.text) for e in events if isinstance(e, RtuFrameEvent)] == TEXTS


def test_garbage_and_a_bad_crc_are_reported_between_good_frames() -> None:
    bad = bytearray(TRAFFIC[0])
    bad[-1] ^= 0x01
    events = decode([b"\x00\xff\x13" + TRAFFIC[2] + bytes(bad) + TRAFFIC[6]])
    frames = [e.text for e in events if isinstance(e, RtuFrameEvent)]
    errors = [e for e in events if isinstance(e, ErrorEvent)]
    assert frames == ["id 2 write 0x0002 target_speed=1500", "id 1 read 0x001E"]
    assert errors and all("dropped" in e.message for e in errors)


def test_the_registry_entry() -> None:
    assert decoder_for(BYTES, "modbus") is DECODER
    assert DECODER.medium == BYTES
    assert DECODER.frame(0x101, b"\x00").is_error


@pytest.mark.parametrize("n", [1, 5])
def test_lines_and_json(n: int) -> None:
    event = decode([TRAFFIC[1]])[0]
    assert isinstance(event, RtuFrameEvent)
    line = event.lines(" " * n)[0]
    assert line.startswith(" " * n + "01 03 04 80 00 00 00") and line.endswith("[32768, 0]")
    assert event.as_dict() == {"raw": TRAFFIC[1].hex(" "), "direction": "drive->host",
                               "text": "id 1 read reply [32768, 0]"}
