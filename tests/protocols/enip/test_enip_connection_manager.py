"""Forward_Open / Forward_Close codecs and the Class 1 connection table (no sockets)."""

from __future__ import annotations

import contextlib
import dataclasses

import enip_raw as raw
import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import FramingError, ProtocolError
from servobus.protocols.enip.codec import connection_manager as cm
from servobus.protocols.enip.codec import epath
from servobus.protocols.enip.codec.connection_manager import (
    ConnectionType,
    ExtendedStatus,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    Priority,
    TransportTrigger,
    Triad,
)
from servobus.protocols.enip.codec.epath import KeySegment, PortSegment
from servobus.protocols.enip.codec.io import IoFrame, OutputImage
from servobus.protocols.enip.connections import ConnectionTable, Refused

TRIAD = Triad(0x1234, 0x4242, 0xCAFE)
PATH = epath.decode_path(raw.DYN5_PATH)


def fo(**kw: object) -> ForwardOpenRequest:
    base = ForwardOpenRequest(0, 0x7000_0001, TRIAD, 10_000,
                              NetworkParameters(10).to_word(), 10_000,
                              NetworkParameters(18).to_word(), 0x01, PATH)
    return dataclasses.replace(base, **kw)  # type: ignore[arg-type]


# ---------------------------------------------------------------- codec
def test_forward_open_matches_the_spec_layout() -> None:
    assert fo().encode() == raw.forward_open_data()
    assert ForwardOpenRequest.decode(raw.forward_open_data()) == fo()
    assert NetworkParameters(10).to_word() == 0x480A  # point-to-point, scheduled, 10 bytes


def test_forward_close_matches_the_spec_layout() -> None:
    req = ForwardCloseRequest(TRIAD, PATH)
    assert req.encode() == raw.forward_close_data()
    assert ForwardCloseRequest.decode(raw.forward_close_data()) == req


def test_forward_open_reply_and_failure_golden() -> None:
    reply = ForwardOpenReply(0x11223344, 0x7000_0001, TRIAD, 10_000, 20_000)
    assert reply.encode() == bytes.fromhex(
        "44332211 01000070 3412 4242 feca0000 10270000 204e0000 00 00")
    assert ForwardOpenReply.decode(reply.encode()) == reply
    fail = cm.ConnectionFailure(TRIAD)
    assert fail.encode() == bytes.fromhex("3412 4242 feca0000 00 00")
    assert cm.ConnectionFailure.decode(fail.encode()) == fail
    close = cm.ForwardCloseReply(TRIAD)
    assert close.encode() == bytes.fromhex("3412 4242 feca0000 00 00")


_u16, _u32 = st.integers(0, 0xFFFF), st.integers(0, 0xFFFF_FFFF)
_triads = st.builds(Triad, _u16, _u16, _u32)
_paths = st.lists(st.builds(epath.LogicalSegment, st.sampled_from(list(epath.LogicalType)),
                            st.integers(0, 255), st.just(8)), max_size=5).map(tuple)


@given(_u32, _u32, _triads, _u32, _u16, _u32, _u16, st.integers(0, 255), _paths,
       st.integers(0, 255), st.integers(0, 255), st.integers(0, 255))
def test_forward_open_round_trip(a: int, b: int, t: Triad, r1: int, p1: int, r2: int, p2: int,
                                 tr: int, path: tuple[epath.Segment, ...], m: int, pt: int,
                                 tt: int) -> None:
    req = ForwardOpenRequest(a, b, t, r1, p1, r2, p2, tr, path, m, pt, tt)
    assert ForwardOpenRequest.decode(req.encode()) == req


@given(_triads, _paths, st.binary(max_size=8).filter(lambda b: len(b) % 2 == 0))
def test_forward_close_and_replies_round_trip(t: Triad, path: tuple[epath.Segment, ...],
                                              app: bytes) -> None:
    assert ForwardCloseRequest.decode(ForwardCloseRequest(t, path).encode()) == \
        ForwardCloseRequest(t, path)
    assert cm.ForwardCloseReply.decode(cm.ForwardCloseReply(t, app).encode()) == \
        cm.ForwardCloseReply(t, app)
    rep = ForwardOpenReply(1, 2, t, 3, 4, app)
    assert ForwardOpenReply.decode(rep.encode()) == rep


@given(st.integers(0, 0x1FF), st.integers(0, 3), st.sampled_from(list(Priority)), st.booleans(),
       st.booleans())
def test_network_parameters_round_trip(size: int, kind: int, prio: Priority, var: bool,
                                       red: bool) -> None:
    p = NetworkParameters(size, kind, prio, var, red)
    assert NetworkParameters.from_word(p.to_word()) == p


@given(st.integers(0, 15), st.integers(0, 7), st.booleans())
def test_transport_trigger_round_trip(cls: int, trig: int, server: bool) -> None:
    t = TransportTrigger(cls, trig, server)
    assert TransportTrigger.from_byte(t.to_byte()) == t


@given(st.binary(max_size=60))
def test_decoders_raise_only_typed_errors(data: bytes) -> None:
    for decode in (ForwardOpenRequest.decode, ForwardCloseRequest.decode,
                   ForwardOpenReply.decode, cm.UnconnectedSendRequest.decode):
        with contextlib.suppress(ProtocolError):
            decode(data)


def test_unconnected_send_round_trip() -> None:
    us = cm.UnconnectedSendRequest(bytes.fromhex("0e03200f24ff30"), (PortSegment(1, b"\0"),))
    enc = us.encode()
    assert enc == bytes.fromhex("0a0e 0700 0e03200f24ff30 00 01 00 0100")
    assert cm.UnconnectedSendRequest.decode(enc) == us


def test_watchdog_formula() -> None:
    assert cm.watchdog_s(10_000, 0) == pytest.approx(0.040)
    assert cm.watchdog_s(10_000, 2) == pytest.approx(0.160)
    assert cm.watchdog_s(250_000, 7) == pytest.approx(128.0)


# ---------------------------------------------------------------- the connection table
def open_ok(table: ConnectionTable, req: ForwardOpenRequest | None = None, now: float = 0.0
            ) -> cm.ForwardOpenReply:
    _, reply = table.open(req or fo(), "127.0.0.1", ("127.0.0.1", 2222), now)
    return reply


def refused(req: ForwardOpenRequest, table: ConnectionTable | None = None) -> Refused:
    with pytest.raises(Refused) as info:
        (table or ConnectionTable()).open(req, "127.0.0.1", ("127.0.0.1", 2222), 0.0)
    return info.value


def test_open_success_reply() -> None:
    table = ConnectionTable()
    reply = open_ok(table)
    assert reply.t_o_connection_id == 0x7000_0001 and reply.triad == TRIAD
    assert reply.o_t_api_us == reply.t_o_api_us == 10_000
    assert list(table.by_o_t_id) == [reply.o_t_connection_id]


def test_path_without_config_and_with_port_and_key() -> None:
    open_ok(ConnectionTable(), fo(path=epath.decode_path(bytes.fromhex("20042c652c64"))))
    key = KeySegment(0xABCD, 127, 1, 1, 1)
    open_ok(ConnectionTable(), fo(path=(PortSegment(1, b"\0"), key, *PATH)))
    open_ok(ConnectionTable(), fo(path=(KeySegment(0, 0, 0, 0, 0), *PATH)))  # wildcard key
    open_ok(ConnectionTable(), fo(path=(KeySegment(0xABCD, 127, 1, 1, 0, True), *PATH)))


def test_duplicate_forward_open() -> None:
    table = ConnectionTable()
    open_ok(table)
    assert refused(fo(), table).status is ExtendedStatus.DUPLICATE_FORWARD_OPEN
    other = fo(triad=Triad(0x9999, 0x4242, 0xCAFE))
    assert refused(other, table).status is ExtendedStatus.OWNERSHIP_CONFLICT


@pytest.mark.parametrize("rpi", [(4999, 10_000), (10_000, 4999), (1000, 1000)])
def test_rpi_below_5_ms_is_not_supported(rpi: tuple[int, int]) -> None:
    r = refused(fo(o_t_rpi_us=rpi[0], t_o_rpi_us=rpi[1]))
    assert r.status is ExtendedStatus.RPI_NOT_SUPPORTED
    open_ok(ConnectionTable(), fo(o_t_rpi_us=5000, t_o_rpi_us=5000))


def test_size_mismatch_names_the_expected_size() -> None:
    r = refused(fo(o_t_params=NetworkParameters(8).to_word()))
    assert (r.status, r.extra) == (ExtendedStatus.INVALID_O_T_SIZE, (10,))
    r = refused(fo(t_o_params=NetworkParameters(16).to_word()))
    assert (r.status, r.extra) == (ExtendedStatus.INVALID_T_O_SIZE, (18,))


@pytest.mark.parametrize("change,status", [
    ({"transport": 0x03}, ExtendedStatus.TRANSPORT_NOT_SUPPORTED),
    ({"transport": 0x11}, ExtendedStatus.TRANSPORT_NOT_SUPPORTED),
    ({"timeout_multiplier": 8}, ExtendedStatus.TIMEOUT_MULTIPLIER_NOT_ACCEPTABLE),
    ({"o_t_params": NetworkParameters(10, ConnectionType.NULL).to_word(),
      "t_o_params": NetworkParameters(18, ConnectionType.NULL).to_word()},
     ExtendedStatus.NULL_FORWARD_OPEN_NOT_SUPPORTED),
    ({"o_t_params": NetworkParameters(10, ConnectionType.MULTICAST).to_word()},
     ExtendedStatus.INVALID_O_T_CONNECTION_TYPE),
    ({"t_o_params": NetworkParameters(18, ConnectionType.MULTICAST).to_word()},
     ExtendedStatus.INVALID_T_O_CONNECTION_TYPE),
    ({"o_t_params": NetworkParameters(10, variable=True).to_word()},
     ExtendedStatus.INVALID_O_T_FIXED_VARIABLE),
    ({"t_o_params": NetworkParameters(18, variable=True).to_word()},
     ExtendedStatus.INVALID_T_O_FIXED_VARIABLE),
])
def test_forward_open_parameter_checks(change: dict[str, int], status: ExtendedStatus) -> None:
    assert refused(fo(**change)).status is status


@pytest.mark.parametrize("path,status", [
    ("20042401 2c652c64", ExtendedStatus.INVALID_CONFIGURATION_PATH),
    ("20042400 2c662c64", ExtendedStatus.INVALID_CONSUMING_PATH),
    ("20042400 2c652c65", ExtendedStatus.INVALID_PRODUCING_PATH),
    ("20042400 2c64", ExtendedStatus.INVALID_SEGMENT_IN_PATH),
    ("20052400 2c652c64", ExtendedStatus.INVALID_SEGMENT_IN_PATH),
    ("2c652c64", ExtendedStatus.INVALID_SEGMENT_IN_PATH),
    ("20042400 2c652c64 3001", ExtendedStatus.INVALID_SEGMENT_IN_PATH),
    ("0200 20042400 2c652c64", ExtendedStatus.PORT_NOT_AVAILABLE),
    ("0103 20042400 2c652c64", ExtendedStatus.LINK_ADDRESS_NOT_VALID),
    ("80010000 20042400 2c652c64", ExtendedStatus.INVALID_CONFIGURATION_SIZE),
    ("3404 cdab 7e00 0100 0101 20042c652c64", ExtendedStatus.DEVICE_TYPE_MISMATCH),
    ("3404 0100 7f00 0100 0101 20042c652c64", ExtendedStatus.VENDOR_OR_PRODUCT_MISMATCH),
    ("3404 cdab 7f00 0200 0101 20042c652c64", ExtendedStatus.VENDOR_OR_PRODUCT_MISMATCH),
    ("3404 cdab 7f00 0100 0201 20042c652c64", ExtendedStatus.REVISION_MISMATCH),
    ("3404 cdab 7f00 0100 0102 20042c652c64", ExtendedStatus.REVISION_MISMATCH),
    ("3404 cdab 7f00 0100 8102 20042c652c64", ExtendedStatus.REVISION_MISMATCH),
])
def test_forward_open_path_checks(path: str, status: ExtendedStatus) -> None:
    segs = epath.decode_path(bytes.fromhex(path))
    assert refused(fo(path=segs)).status is status


def test_forward_close_match_and_mismatch() -> None:
    table = ConnectionTable()
    open_ok(table)
    for bad_triad in (Triad(0x1235, 0x4242, 0xCAFE), Triad(0x1234, 0x4243, 0xCAFE),
                      Triad(0x1234, 0x4242, 0xCAFF)):
        with pytest.raises(Refused) as info:
            table.close(ForwardCloseRequest(bad_triad, PATH), "127.0.0.1")
        assert info.value.status is ExtendedStatus.CONNECTION_NOT_FOUND
    with pytest.raises(Refused) as info:
        table.close(ForwardCloseRequest(TRIAD, PATH), "127.0.0.9")  # not the originator
    assert info.value.status is ExtendedStatus.CONNECTION_NOT_FOUND
    other = epath.decode_path(bytes.fromhex("20042400 2c662c64"))
    with pytest.raises(Refused) as info:
        table.close(ForwardCloseRequest(TRIAD, other), "127.0.0.1")
    assert info.value.status is ExtendedStatus.FORWARD_CLOSE_PATH_MISMATCH
    assert len(table) == 1
    table.close(ForwardCloseRequest(TRIAD, ()), "127.0.0.1")  # an empty path matches
    assert len(table) == 0
    open_ok(table)  # the triad may be used again


def test_consume_sequence_rules_and_watchdog() -> None:
    table = ConnectionTable()
    reply = open_ok(table, now=100.0)
    conn = table.by_o_t_id[reply.o_t_connection_id]
    assert conn.deadline == 110.0  # at least 10 s before the first O->T frame
    assert conn.timeout_s == pytest.approx(0.040)
    oid = reply.o_t_connection_id

    def frame(seq: int, count: int, word: int, run: bool = True) -> IoFrame:
        return IoFrame(oid, seq, count, OutputImage(word, run).encode())

    got = table.consume(frame(1, 1, 0xAAAA), "127.0.0.1", 100.0)
    assert got is not None and got.apply and conn.deadline == pytest.approx(100.04)
    assert table.consume(frame(1, 2, 0xDEDE), "127.0.0.1", 100.01) is None  # not newer
    assert table.consume(frame(2, 2, 0xDEDE), "127.0.0.2", 100.01) is None  # other IP
    assert table.consume(IoFrame(oid + 1, 2, 2, b""), "127.0.0.1", 100.01) is None
    same = table.consume(frame(2, 1, 0xDEDE), "127.0.0.1", 100.02)  # same count: no new data
    assert same is not None and not same.apply and conn.deadline == pytest.approx(100.06)
    again = table.consume(frame(3, 2, 0xAAAA), "127.0.0.1", 100.03)  # same word: no edge
    assert again is not None and not again.apply
    idle = table.consume(frame(4, 3, 0xDEDE, run=False), "127.0.0.1", 100.04)
    assert idle is not None and not idle.apply  # idle: data not applied
    run = table.consume(frame(5, 4, 0xDEDE), "127.0.0.1", 100.05)
    assert run is not None and run.apply
    other = table.consume(frame(6, 5, 0x1234), "127.0.0.1", 100.06)
    assert other is not None and not other.apply  # neither enable nor disable
    assert table.consume(IoFrame(oid, 7, 6, b"\x01"), "127.0.0.1", 100.07) is None
    assert table.expired(100.09) == []
    assert table.expired(100.11) == [conn] and len(table) == 0


def test_consume_sequence_wraps() -> None:
    table = ConnectionTable()
    reply = open_ok(table)
    oid = reply.o_t_connection_id
    img = OutputImage(0xAAAA).encode()
    assert table.consume(IoFrame(oid, 0xFFFF_FFFF, 0xFFFF, img), "127.0.0.1", 0.0) is not None
    assert table.consume(IoFrame(oid, 0, 0, img), "127.0.0.1", 0.0) is not None


def test_production_counters_advance_together() -> None:
    table = ConnectionTable()
    conn = table.by_o_t_id[open_ok(table).o_t_connection_id]
    assert [conn.next_production() for _ in range(3)] == [(1, 1), (2, 2), (3, 3)]
    conn.produced_sequence, conn.produced_count = 0xFFFF_FFFF, 0xFFFF
    assert conn.next_production() == (0, 0)


def test_forward_open_decode_rejects_bad_path_size() -> None:
    data = raw.forward_open_data()
    with pytest.raises(FramingError):
        ForwardOpenRequest.decode(data + b"\0\0")
    with pytest.raises(FramingError):
        ForwardOpenRequest.decode(data[:-2])
