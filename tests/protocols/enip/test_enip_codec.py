"""EtherNet/IP codecs: encapsulation, CPF, EPATH, Message Router, discovery items, Identity."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import FramingError, ProtocolError
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.codec import cpf, discovery, epath
from servobus.protocols.enip.codec import identity as ident
from servobus.protocols.enip.codec.cip import (
    MessageRouterRequest,
    MessageRouterResponse,
    RequestTarget,
    request_target,
)
from servobus.protocols.enip.codec.cpf import CpfItem, ItemType, RRData, SockaddrInfo
from servobus.protocols.enip.codec.encap import (
    Command,
    EncapHeader,
    EncapPacket,
    RegisterSessionData,
)
from servobus.protocols.enip.codec.epath import (
    DataSegment,
    KeySegment,
    LogicalSegment,
    LogicalType,
    NetworkSegment,
    PortSegment,
)

CTX = b"_pycomm_"


# ---------------------------------------------------------------- encapsulation
def test_register_session_golden() -> None:
    raw = bytes.fromhex("6500 0400 00000000 00000000") + CTX + bytes.fromhex("00000000 0100 0000")
    pkt = EncapPacket.decode(raw)
    assert pkt.command == Command.REGISTER_SESSION and pkt.context == CTX
    assert RegisterSessionData.decode(pkt.data) == RegisterSessionData(1, 0)
    reply = pkt.reply(RegisterSessionData().encode(), session=0x11223344)
    assert reply.encode() == (bytes.fromhex("6500 0400 44332211 00000000") + CTX
                              + bytes.fromhex("00000000 0100 0000"))


def test_header_is_little_endian_24_bytes() -> None:
    head = EncapHeader(0x006F, 0x1234, 0xA1B2C3D4, 0x65, b"ABCDEFGH", 0)
    raw = head.encode()
    assert raw == bytes.fromhex("6f00 3412 d4c3b2a1 65000000") + b"ABCDEFGH" + bytes(4)
    assert EncapHeader.decode(raw) == head


@given(st.integers(0, 0xFFFF), st.binary(max_size=64), st.integers(0, 0xFFFF_FFFF),
       st.integers(0, 0xFFFF_FFFF), st.binary(min_size=8, max_size=8),
       st.integers(0, 0xFFFF_FFFF))
def test_packet_round_trip(cmd: int, data: bytes, session: int, status: int, ctx: bytes,
                           options: int) -> None:
    pkt = EncapPacket(cmd, data, session, status, ctx, options)
    assert EncapPacket.decode(pkt.encode()) == pkt


def test_packet_decode_checks_length() -> None:
    raw = EncapPacket(Command.NOP, b"abc").encode()
    with pytest.raises(FramingError):
        EncapPacket.decode(raw + b"x")
    with pytest.raises(FramingError):
        EncapPacket.decode(raw[:10])
    with pytest.raises(FramingError):
        RegisterSessionData.decode(b"\x01\x00")


# ---------------------------------------------------------------- CPF
def test_unconnected_send_rr_data_golden() -> None:
    mr = bytes.fromhex("0e03200f24ff3001")  # manual 6.1: Get_Attribute_Single 0x0F/0xFF/1
    rr = RRData(cpf.unconnected(mr), 0, 5)
    assert rr.encode() == bytes.fromhex("00000000 0500 0200 0000 0000 b200 0800") + mr
    assert RRData.decode(rr.encode()) == rr


def test_sockaddr_is_big_endian() -> None:
    sa = SockaddrInfo(2222, "192.168.50.18")
    assert sa.encode() == bytes.fromhex("0002 08ae c0a83212") + bytes(8)
    assert SockaddrInfo.decode(sa.encode()) == sa
    item = sa.item(ItemType.SOCKADDR_T_O)
    assert cpf.encode_items((item,))[:6] == bytes.fromhex("0100 0180 1000")


@given(st.lists(st.builds(CpfItem, st.integers(0, 0xFFFF), st.binary(max_size=40)),
                max_size=5))
def test_cpf_round_trip(items: list[CpfItem]) -> None:
    assert cpf.decode_items(cpf.encode_items(items)) == tuple(items)


@given(st.integers(0, 0xFFFF), st.ip_addresses(v=4).map(str))
def test_sockaddr_round_trip(port: int, address: str) -> None:
    sa = SockaddrInfo(port, address)
    assert SockaddrInfo.decode(sa.encode()) == sa


@given(st.binary(max_size=64))
def test_cpf_decoder_raises_only_typed_errors(raw: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        cpf.decode_items(raw)
        cpf.UnconnectedMessage.from_items(cpf.decode_items(raw))


def test_unconnected_message_roles() -> None:
    t_o = SockaddrInfo(40000, "127.0.0.1")
    msg = cpf.UnconnectedMessage(b"\x01\x02", sockaddr_t_o=t_o)
    assert cpf.UnconnectedMessage.from_items(msg.items()) == msg
    with pytest.raises(FramingError):
        cpf.UnconnectedMessage.from_items((CpfItem(ItemType.UNCONNECTED_DATA, b"x"),))
    with pytest.raises(FramingError):
        cpf.UnconnectedMessage.from_items(cpf.unconnected(b"x", CpfItem(0x00A1, bytes(4))))


# ---------------------------------------------------------------- EPATH
def test_paths_of_notes_with_and_without_config() -> None:
    with_cfg = epath.decode_path(bytes.fromhex("20042400 2c652c64"))
    assert with_cfg == (LogicalSegment(LogicalType.CLASS, 4, 8),
                        LogicalSegment(LogicalType.INSTANCE, 0, 8),
                        LogicalSegment(LogicalType.CONNECTION_POINT, 0x65, 8),
                        LogicalSegment(LogicalType.CONNECTION_POINT, 0x64, 8))
    assert epath.decode_path(bytes.fromhex("20042c652c64")) == (with_cfg[0], *with_cfg[2:])
    assert epath.encode_path(with_cfg) == bytes.fromhex("200424002c652c64")


def test_16_bit_and_32_bit_logical_segments_are_padded() -> None:
    path = (LogicalSegment(LogicalType.CLASS, 0x0F), LogicalSegment(LogicalType.INSTANCE, 0x1234),
            LogicalSegment(LogicalType.ATTRIBUTE, 0x0102, 16),
            LogicalSegment(LogicalType.CONNECTION_POINT, 0x10000))
    raw = epath.encode_path(path)
    assert raw == bytes.fromhex("200f 2500 3412 3100 0201 2e00 00000100")
    assert [s.value for s in epath.decode_path(raw)] == [0x0F, 0x1234, 0x0102, 0x10000]


def test_port_key_data_network_segments() -> None:
    raw = bytes.fromhex("0100 3404 cdab 7f00 0100 0101 4305 8001 aabb")
    assert epath.decode_path(raw) == (
        PortSegment(1, b"\x00"), KeySegment(0xABCD, 127, 1, 1, 1), NetworkSegment(0x43, 5),
        DataSegment(b"\xaa\xbb"))
    ext = PortSegment(18, b"10.0.0.1")  # extended port id and link address (odd size padded)
    assert epath.decode_path(epath.encode_path((ext,))) == (ext,)
    assert epath.encode_path((PortSegment(2, b"abc"),)) == bytes.fromhex("1203 616263 00")


_logical = st.builds(LogicalSegment, st.sampled_from(list(LogicalType)),
                     st.integers(0, 0xFF), st.just(8)) | st.builds(
    LogicalSegment, st.sampled_from(list(LogicalType)), st.integers(0, 0xFFFF), st.just(16)) | \
    st.builds(LogicalSegment, st.sampled_from(list(LogicalType)), st.integers(0, 0xFFFF_FFFF),
              st.just(32))
_segment = _logical | st.builds(PortSegment, st.integers(1, 0xFFFF),
                                st.binary(min_size=1, max_size=9)) | st.builds(
    KeySegment, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF),
    st.integers(0, 127), st.integers(0, 255), st.booleans()) | st.builds(
    DataSegment, st.binary(max_size=20).filter(lambda b: len(b) % 2 == 0)) | st.builds(
    NetworkSegment, st.integers(0x40, 0x4F), st.integers(0, 255))


@given(st.lists(_segment, max_size=6))
def test_epath_round_trip(segs: list[epath.Segment]) -> None:
    raw = epath.encode_path(segs)
    assert len(raw) % 2 == 0
    assert epath.decode_path(raw) == tuple(segs)


@given(st.binary(max_size=40))
def test_epath_decoder_raises_only_typed_errors(raw: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        epath.decode_path(raw)


@pytest.mark.parametrize("raw", ["20", "2500ff", "0f", "3404cdab", "8002aa", "e000", "2300"])
def test_bad_paths(raw: str) -> None:
    with pytest.raises(FramingError):
        epath.decode_path(bytes.fromhex(raw))


# ---------------------------------------------------------------- Message Router
def test_request_golden_manual_6_1_and_6_2() -> None:
    req = MessageRouterRequest(0x0E, epath.request_path(0x0F, 0xFF, 1))
    assert req.encode() == bytes.fromhex("0e03200f24ff3001")
    speed = MessageRouterRequest(0x10, epath.request_path(0x0F, 0x0E, 1),
                                 dyn5.encode_udint(500))
    assert speed.encode() == bytes.fromhex("1003200f240e3001 f4010000")
    assert MessageRouterRequest.decode(speed.encode()) == MessageRouterRequest(
        0x10, (LogicalSegment(LogicalType.CLASS, 0x0F, 8),
               LogicalSegment(LogicalType.INSTANCE, 0x0E, 8),
               LogicalSegment(LogicalType.ATTRIBUTE, 1, 8)), dyn5.encode_udint(500))


def test_response_golden() -> None:
    ok = MessageRouterResponse(0x0E, data=dyn5.encode_udint(0x12345))
    assert ok.encode() == bytes.fromhex("8e000000 45230100")
    err = MessageRouterResponse(0x54, 0x01, (0x0111,), b"\x01\x02")
    assert err.encode() == bytes.fromhex("d4000101 1101 0102")
    assert MessageRouterResponse.decode(err.encode()) == err


@given(st.integers(0, 0x7F), st.lists(_logical, max_size=4), st.binary(max_size=20))
def test_request_round_trip(service: int, path: list[LogicalSegment], data: bytes) -> None:
    req = MessageRouterRequest(service, tuple(path), data)
    assert MessageRouterRequest.decode(req.encode()) == req


@given(st.integers(0, 0x7F), st.integers(0, 0xFF), st.lists(st.integers(0, 0xFFFF), max_size=3),
       st.binary(max_size=20))
def test_response_round_trip(service: int, status: int, extra: list[int], data: bytes) -> None:
    resp = MessageRouterResponse(service, status, tuple(extra), data)
    assert MessageRouterResponse.decode(resp.encode()) == resp


@given(st.binary(max_size=30))
def test_message_router_decoders_raise_only_typed_errors(raw: bytes) -> None:
    for decode in (MessageRouterRequest.decode, MessageRouterResponse.decode):
        with contextlib.suppress(ProtocolError):
            decode(raw)


def test_request_target_shapes() -> None:
    assert request_target(epath.request_path(1, 1, 7)) == RequestTarget(1, 1, 7)
    assert request_target(epath.request_path(0x0F, 0x1FF)) == RequestTarget(0x0F, 0x1FF)
    for bad in ((LogicalSegment(LogicalType.CLASS, 1),),
                (LogicalSegment(LogicalType.INSTANCE, 1), LogicalSegment(LogicalType.CLASS, 1)),
                (PortSegment(1, b"\0"), *epath.request_path(1, 1)),
                (*epath.request_path(1, 1, 1), LogicalSegment(LogicalType.ATTRIBUTE, 2))):
        with pytest.raises(FramingError):
            request_target(bad)


def test_truncated_request_path() -> None:
    with pytest.raises(FramingError):
        MessageRouterRequest.decode(bytes.fromhex("0e05200f24ff3001"))
    with pytest.raises(FramingError):
        MessageRouterRequest.decode(bytes.fromhex("8e00"))


# ---------------------------------------------------------------- discovery and Identity
def test_list_identity_item_golden() -> None:
    i = dyn5.IDENTITY
    item = discovery.IdentityItem(SockaddrInfo(44818, "192.168.50.18"), i.vendor_id,
                                  i.device_type, i.product_code, i.revision, i.status,
                                  i.serial_number, i.product_name, i.state)
    raw = item.encode()
    assert raw == (bytes.fromhex("0100 0002 af12 c0a83212") + bytes(8)
                   + bytes.fromhex("cdab 7f00 0100 01 01 0000 01000000 08")
                   + b"DYN5ENIP" + b"\x03")
    assert discovery.decode_identity_reply(discovery.list_identity_reply(item)) == item


def test_list_services_and_interfaces_golden() -> None:
    raw = discovery.list_services_reply()
    assert raw == bytes.fromhex("0100 0001 1400 0100 2001") + b"Communications\0\0"
    assert discovery.ServiceItem.decode(raw[6:]) == discovery.ServiceItem()
    assert discovery.list_interfaces_reply() == b"\x00\x00"


def test_identity_attributes() -> None:
    i = dyn5.IDENTITY
    assert ident.instance_attribute(i, 1) == bytes.fromhex("cdab")
    assert ident.instance_attribute(i, 2) == bytes.fromhex("7f00")
    assert ident.instance_attribute(i, 4) == bytes((1, 1))
    assert ident.instance_attribute(i, 6) == bytes.fromhex("01000000")
    assert ident.instance_attribute(i, 7) == b"\x08DYN5ENIP"
    assert ident.instance_attribute(i, 8) is None
    reply = ident.IdentityReply.decode(ident.all_attributes(i))
    assert reply == ident.IdentityReply(0xABCD, 127, 1, (1, 1), 0, 1, "DYN5ENIP")
    assert ident.class_all_attributes() == bytes.fromhex("0100 0100 0100 0700 0700")
    assert ident.class_attribute(4) is None



def test_identity_attributes_and_list_identity_item_share_one_layout() -> None:
    """Every field a different value, so a swapped or resized field shows; the expected
    bytes are written out by hand (CIP Vol. 1 5A-2, Vol. 2 2-4), not derived from the codec."""
    i = dyn5.Identity(vendor_id=0x1234, device_type=0x0056, product_code=0x789A,
                      revision=(2, 7), status=0x0BCD, serial_number=0x01020304,
                      product_name="AB", state=5)
    singles = {1: "3412", 2: "5600", 3: "9a78", 4: "0207", 5: "cd0b", 6: "04030201",
               7: "02 4142"}
    for attribute, expected in singles.items():
        assert ident.instance_attribute(i, attribute) == bytes.fromhex(expected)
    assert ident.instance_attribute(i, 0) is None
    attributes = bytes.fromhex("3412 5600 9a78 0207 cd0b 04030201 02 4142")
    assert ident.all_attributes(i) == attributes
    reply = ident.IdentityReply(0x1234, 0x56, 0x789A, (2, 7), 0x0BCD, 0x01020304, "AB")
    assert ident.IdentityReply.decode(attributes) == reply
    item = discovery.IdentityItem(SockaddrInfo(2222, "10.0.0.9"), i.vendor_id, i.device_type,
                                  i.product_code, i.revision, i.status, i.serial_number,
                                  i.product_name, i.state)
    raw = bytes.fromhex("0100 0002 08ae 0a000009") + bytes(8) + attributes + b"\x05"
    assert item.encode() == raw
    assert discovery.IdentityItem.decode(raw) == item


def test_identity_field_out_of_range_is_a_framing_error() -> None:
    with pytest.raises(FramingError):
        ident.all_attributes(dyn5.Identity(serial_number=1 << 32))
    with pytest.raises(FramingError):
        discovery.IdentityItem(SockaddrInfo(1, "10.0.0.9"), 0x10000, 0, 0, (1, 1), 0, 0,
                               "X", 3).encode()
    with pytest.raises(FramingError):
        ident.all_attributes(dyn5.Identity(product_name="é"))

@given(st.builds(discovery.IdentityItem, st.builds(SockaddrInfo, st.integers(0, 0xFFFF),
                                                     st.ip_addresses(v=4).map(str)),
                 st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF),
                 st.tuples(st.integers(0, 255), st.integers(0, 255)), st.integers(0, 0xFFFF),
                 st.integers(0, 0xFFFF_FFFF), st.text("ABCXYZ0123", max_size=32),
                 st.integers(0, 255)))
def test_identity_item_round_trip(item: discovery.IdentityItem) -> None:
    assert discovery.IdentityItem.decode(item.encode()) == item
