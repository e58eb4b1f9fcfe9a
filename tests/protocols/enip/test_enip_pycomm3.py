"""Interoperability: pycomm3's CIPDriver (an independent CIP client) against the virtual DYN5:
Identity, Parameter reads/writes, the DYN5 error 05, ListIdentity."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from pycomm3 import DINT, UDINT, CIPDriver, Services
from rig import wait_until

from servobus.protocols.enip.server import BackgroundEnip, EnipServer

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(scope="module")
def background() -> Iterator[BackgroundEnip]:
    with BackgroundEnip() as bg:
        yield bg


@pytest.fixture(scope="module")
def server(background: BackgroundEnip) -> EnipServer:
    return background.servers[0]


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


def test_a_torque_command_is_not_soft_started(background: BackgroundEnip,
                                              plc: CIPDriver) -> None:
    """DYN5 section 7: torque commands "become effective in the servo loop after <=300us"
    (checked on simulated time in test_enip_torque_latency). At High Accel 1 the DYN2's
    analog soft start would take 60 s from 10 to 90 % (issue 34); the network command is
    there at once. Shaft blocked (back-EMF plays no part); Motor Torque 0x1F is CCW-positive."""
    get, put = Services.get_attribute_single, Services.set_attribute_single
    drive = background.servers[0].drive
    background.call(lambda: drive.set_blocked(True))
    high_accel = message(plc, get, 0x0F, 0x09, 1, data_type=UDINT).value
    try:
        for inst, value in ((0x09, 1), (0x25, 0xFFFF), (0x0D, 0xAAAA), (0x26, 150)):
            assert message(plc, put, 0x0F, inst, 1, request_data=UDINT.encode(value)).error \
                is None
        wait_until(lambda: message(plc, get, 0x0F, 0x1F, 1, data_type=DINT).value == -150,
                   timeout=30, what="Motor Torque -150 (a soft start at High Accel 1: ~60 s)")
    finally:
        for inst, value in ((0x26, 0), (0x25, 0), (0x09, high_accel)):
            message(plc, put, 0x0F, inst, 1, request_data=UDINT.encode(value))
        background.call(lambda: drive.set_blocked(False))
