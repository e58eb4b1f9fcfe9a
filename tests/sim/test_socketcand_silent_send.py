"""The socketcand hub drops a malformed ``send`` without a reply, as socketcand does (issue 34):
python-can's socketcand client reads any ``< error ... >`` line as a frame, fails to parse it
and ends its session. In-process hub, python-can and a raw client in a worker thread."""

from __future__ import annotations

import asyncio
import time

import can
import pytest
from sim_abuse_rig import can_session, expect

from servobus.sim.socketcand_hub import SocketcandHub

pytestmark = pytest.mark.timeout(60)
DEADLINE_S = 10.0  # generous: a loaded machine

MALFORMED = (b"< send 12\xff 1 00 >", b"< send -1 0 >", b"< send 800 0 >",
             b"< send 123 9 1 2 3 4 5 6 7 8 9 >", b"< send 123 1 zz >", b"< send >")


def recv_id(bus: can.BusABC, ident: int) -> can.Message:
    end = time.monotonic() + DEADLINE_S
    while (left := end - time.monotonic()) > 0:
        msg = bus.recv(left)  # an ``< error >`` line here raised CanError before the fix
        if msg is not None and msg.arbitration_id == ident:
            return msg
    raise AssertionError(f"no frame {ident:03X} within {DEADLINE_S} s")


def python_can_session(port: int) -> None:
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
    raw = can_session(port)
    try:
        # python-can's own malformed send: a 12-byte FD frame is written "< send 123 C ... >",
        # which classic CAN cannot carry; before the fix the hub's error line reached it.
        bus.send(can.Message(arbitration_id=0x123, data=bytes(range(12)), is_fd=True,
                             is_extended_id=False))
        for message in MALFORMED:  # another client's malformed sends
            raw.sendall(message)
        raw.sendall(b"< send 0AB 2 1 ff >")
        assert bytes(recv_id(bus, 0x0AB).data) == b"\x01\xff"  # python-can still reads
        bus.send(can.Message(arbitration_id=0x0CD, data=b"\x07", is_extended_id=False))
        got = expect(raw, b"< frame 0CD ", DEADLINE_S)  # ... and still sends
        raw.sendall(b"< echo >")
        got += expect(raw, b"< echo >", DEADLINE_S)
        assert b"error" not in got  # no reply to any malformed send
        assert b"< frame 123 " not in got  # nothing malformed was relayed
    finally:
        raw.close()
        bus.shutdown()


async def test_python_can_stays_alive_after_malformed_sends() -> None:
    hub = SocketcandHub()
    _, port = await hub.start()
    try:
        await asyncio.to_thread(python_can_session, port)
    finally:
        await hub.close()
