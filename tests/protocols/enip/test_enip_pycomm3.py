"""Interoperability: pycomm3's CIPDriver (an independent CIP client) against the virtual DYN5:
Identity, Parameter reads/writes, the DYN5 error 05, ListIdentity."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from pycomm3 import DINT, UDINT, CIPDriver, Services

from servobus.protocols.enip.server import BackgroundEnip, EnipServer

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(scope="module")
def server() -> Iterator[EnipServer]:
    with BackgroundEnip() as bg:
        yield bg.servers[0]


@pytest.fixture
def plc(server: EnipServer) -> Iterator[CIPDriver]:
    with CIPDriver(f"{server.host}:{server.tcp_port}") as driver:
        yield driver


def message(plc: CIPDriver, service: int, cls: int, inst: int, attr: int | bytes = b"",
            **kw: object):  # type: ignore[no-untyped-def]
    return plc.generic_message(service=service, class_code=cls, instance=inst, attribute=attr,
                               connected=False, route_path=False, **kw)


def test_identity_get_attributes_all(plc: CIPDriver) -> None:
    from pycomm3.custom_types import ModuleIdentityObject

    tag = message(plc, Services.get_attributes_all, 0x01, 1, data_type=ModuleIdentityObject)
    assert tag.error is None
    assert tag.value["product_name"] == "DYN5ENIP"
    assert tag.value["product_code"] == 1
    assert tag.value["revision"] == {"major": 1, "minor": 1}
    assert tag.value["serial"] == "00000001"


def test_identity_single_attributes(plc: CIPDriver) -> None:
    from pycomm3 import SHORT_STRING, UINT

    assert message(plc, Services.get_attribute_single, 0x01, 1, 1, data_type=UINT).value == 0xABCD
    assert message(plc, Services.get_attribute_single, 0x01, 1, 2, data_type=UINT).value == 127
    assert message(plc, Services.get_attribute_single, 0x01, 1, 6,
                   data_type=UDINT).value == 1
    assert message(plc, Services.get_attribute_single, 0x01, 1, 7,
                   data_type=SHORT_STRING).value == "DYN5ENIP"


def test_parameter_read_write(plc: CIPDriver) -> None:
    get, put = Services.get_attribute_single, Services.set_attribute_single
    first = message(plc, get, 0x0F, 0xFF, 1, data_type=UDINT).value
    assert message(plc, get, 0x0F, 0xFF, 1, data_type=UDINT).value == (first + 1) % 256
    assert message(plc, put, 0x0F, 0x01, 1, request_data=UDINT.encode(21)).error is None
    assert message(plc, get, 0x0F, 0x01, 1, data_type=UDINT).value == 21
    assert message(plc, put, 0x0F, 0x04, 1, request_data=UDINT.encode(55)).error is None
    assert message(plc, get, 0x0F, 0x04, 1, data_type=UDINT).value == 55
    assert message(plc, get, 0x0F, 0x15, 1, data_type=UDINT).value == 0x12345  # write-only
    assert message(plc, put, 0x0F, 0x0E, 1, request_data=DINT.encode(-120)).error is None
    assert message(plc, get, 0x0F, 0x0D, 1, data_type=UDINT).value == 0xAAAA


def test_gear_num_below_500_is_accepted_over_the_wire(plc: CIPDriver) -> None:
    """4.3: GEAR_NUM 1~16384 (issue 18.2: 1..499 answered 05 before)."""
    get, put = Services.get_attribute_single, Services.set_attribute_single
    try:
        assert message(plc, put, 0x0F, 0x0B, 1, request_data=UDINT.encode(1)).error is None
        assert message(plc, get, 0x0F, 0x0B, 1, data_type=UDINT).value == 1
        assert message(plc, put, 0x0F, 0x0B, 1, request_data=UDINT.encode(0)).error is not None
    finally:
        message(plc, put, 0x0F, 0x0B, 1, request_data=UDINT.encode(4096))


def test_dyn5_error_05_reaches_pycomm3(plc: CIPDriver) -> None:
    bad = message(plc, Services.set_attribute_single, 0x0F, 0x01, 1,
                  request_data=UDINT.encode(64))
    assert bad.error is not None and "destination unknown" in bad.error.lower()
    short = message(plc, Services.set_attribute_single, 0x0F, 0x01, 1, request_data=b"\x01\x00")
    assert short.error is not None
    assert message(plc, Services.get_attribute_single, 0x0F, 0x01, 1,
                   data_type=UDINT).error is None


def test_list_identity(server: EnipServer) -> None:
    identity = CIPDriver.list_identity(f"{server.host}:{server.tcp_port}")
    assert identity is not None
    assert identity["product_name"] == "DYN5ENIP" and identity["ip_address"] == "127.0.0.1"
    assert identity["state"] == 3
