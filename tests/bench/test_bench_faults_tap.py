"""The fault run's motion tap counts a motion frame sent twice, whatever the protocol, and
nothing else: its 'motion commands re-sent' figure can be other than 0."""

from __future__ import annotations

import struct

import pytest

from benchmarks.fault_proxy import MotionTap
from servobus.protocols.enip.codec import cpf
from servobus.protocols.enip.codec.encap import EncapPacket


def enip_set(instance: int, value: int, session: int) -> bytes:
    message = bytes((0x10, 3, 0x20, 0x0F, 0x24, instance, 0x30, 1)) + struct.pack("<i", value)
    return EncapPacket(0x6F, cpf.plain_rr_data(message), session, context=b"servobus").encode()


#: protocol -> (a move to an absolute target, traffic that is no motion: reads and a stop),
#: as each client sends them (socketcand: the client's text lines).
TRAFFIC = {
    "dyn232": (bytes.fromhex("01 c1 80 c0 80 82"),  # GO_ABSOLUTE_POS 8192
               bytes.fromhex("01 89 80 8a 01 8a 80 8b")),  # READ_DRIVE_STATUS, speed 0
    "dyncan": (b"< send 021 2 20 00 >", b"< send 029 1 00 >< send 02a 1 00 >"),
    "easycan": (b"< send 001 8 ff 06 16 02 00 40 00 00 >",  # WRITE absolute_position
                b"< send 001 4 ff 03 16 02 >< send 001 6 ff 06 02 01 00 00 >"),
    "modbus": (bytes.fromhex("01 10 00 16 00 02 04 40 00 00 00 67 49"),
               bytes.fromhex("01 03 00 01 00 17 54 04")),
    "enip": (enip_set(0x15, 8192, session=1), enip_set(0x0E, 0, session=1)),
}


@pytest.mark.parametrize("protocol", sorted(TRAFFIC))
def test_a_motion_frame_seen_twice_is_one_resent(protocol: str) -> None:
    move, other = TRAFFIC[protocol]
    tap = MotionTap(protocol)
    first = tap.connection()
    for i in range(0, len(other + move), 3):  # any chunking
        first((other + move)[i:i + 3])
    assert (tap.frames, tap.resent) == (1, 0)
    if protocol == "enip":  # a new session after a reconnect: the same command
        move = enip_set(0x15, 8192, session=2)
    tap.connection()(other + move)  # a second connection (after a reconnect)
    assert (tap.frames, tap.resent) == (2, 1)
