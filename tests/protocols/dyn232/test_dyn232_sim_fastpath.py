"""Dyn232Line.handle_whole (the cached one-packet fast path) == the framed byte path."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.device import Dyn232Line
from servobus.sim.dmm.drive import VirtualDrive

IDS = (0, 1, 2, 3, c.BROADCAST_ID, 9)  # 9 is absent; 127 reaches every drive


def _line() -> Dyn232Line:
    return Dyn232Line([VirtualDrive(i) for i in (1, 2, 3)])


def _state(line: Dyn232Line) -> list[tuple[object, ...]]:
    return [
        (d.drive_id, d.position, d.peek_status().to_byte(), d.read_config().to_byte(),
         tuple(d.get_param(n) for n in ("main_gain", "max_speed", "gear_num", "on_range")))
        for d in line.drives
    ] + [(line.packets, line.checksum_errors)]


packets = st.builds(
    lambda i, f, v, corrupt: (lambda raw: raw[:-1] + bytes([raw[-1] ^ 0x01]) if corrupt
                              else raw)(c.encode(i, f, v)),
    st.sampled_from(IDS), st.sampled_from(c.HOST_FUNCTIONS),
    st.one_of(st.integers(-70, 140), st.sampled_from([0x1B, 0x1C, 0x1D, 0x1E, 0x20, 0x21,
                                                        500, 4096, 16384, 20_000])),
    st.booleans(),
)


@settings(max_examples=60, deadline=None)
@given(st.lists(packets, min_size=1, max_size=25))
def test_fast_path_replies_and_state_match_the_framed_path(seq: list[bytes]) -> None:
    slow, fast = _line(), _line()
    for raw in seq:
        for d in (*slow.drives, *fast.drives):
            d.advance(0.01)
        assert fast.handle_whole(raw) == slow.receive(raw), raw.hex(" ")
    assert _state(fast) == _state(slow)


def test_repeated_request_is_served_from_the_cache_with_fresh_values() -> None:
    line = _line()
    poll = c.encode(2, DmmFunction.GENERAL_READ, int(c.GeneralReadSelector.POSITION))
    first = c.decode(line.handle_whole(poll)).reply_value()
    line.drives[1].move_relative(1000)
    line.drives[1].advance(1.0)
    second = c.decode(line.handle_whole(poll)).reply_value()
    assert first == 0 and abs(second - 4000) <= 40  # within OnRange of 1000 x 4 counts
