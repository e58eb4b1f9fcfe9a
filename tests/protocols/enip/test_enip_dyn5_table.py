"""The DYN5 device model (servobus.families.dyn5.params) against the manual's tables."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError
from servobus.families.dmm import params as P
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.params import Access

# (instance, access, minimum, maximum or choices) as section 4.3 lists them, with the
# decisions of the module docstring applied (0x20 1..127, 0x22 = 34).
SPEC_4_3 = [
    (0x01, "RW", 0, 63), (0x02, "R", 0, 65535), (0x03, "RW", (0xFFFF,), None),
    (0x04, "RW", 1, 127), (0x05, "RW", 1, 127), (0x06, "RW", 1, 127), (0x07, "RW", 1, 127),
    (0x08, "RW", 1, 127), (0x09, "RW", 1, 127), (0x0A, "RW", 1, 127),
    (0x0B, "RW", 1, 16384), (0x0C, "RW", 1, 4095), (0x0D, "RW", (0xAAAA, 0xDEDE), None),
    (0x0E, "W", -16384, 16384), (0x0F, "W", 0, 4096), (0x11, "W", 0, 4096),
    (0x13, "W", 0, 60), (0x14, "R", None, None), (0x15, "W", -134217728, 134217727),
    (0x17, "W", -134217728, 134217727), (0x1D, "R", -134217728, 134217727),
    (0x1F, "R", -2000, 2000), (0x20, "RW", 1, 127), (0x21, "W", (0xABCD,), None),
    (0x22, "R", None, None), (0x25, "RW", (0x0000, 0xFFFF), None), (0x26, "W", -2000, 2000),
    (0x27, "RW", 1, 20000), (0xFF, "R", 0, 255),
]


def test_every_instance_of_section_4_3_and_nothing_else() -> None:
    assert sorted(dyn5.BY_NUMBER) == [row[0] for row in SPEC_4_3]
    assert len(dyn5.BY_NAME) == len(dyn5.INSTANCES)


@pytest.mark.parametrize("number,access,lo,hi", SPEC_4_3)
def test_access_and_range(number: int, access: str, lo: object, hi: object) -> None:
    inst = dyn5.instance(number)
    assert inst.access is Access(access)
    if isinstance(lo, tuple):
        assert inst.choices == lo
        for value in lo:
            assert inst.valid(value)
        assert not inst.valid(lo[0] + 1)
    elif lo is not None and inst.writable:
        assert inst.valid(lo) and inst.valid(hi)  # type: ignore[arg-type]
        assert not inst.valid(lo - 1) and not inst.valid(hi + 1)  # type: ignore[operator]
    elif lo is not None:
        assert (inst.minimum, inst.maximum) == (lo, hi)


def test_readability_quirks() -> None:
    unreadable = {i.number for i in dyn5.INSTANCES if not i.readable}
    # write-only instances read 0x12345 (4.1), except 0x26 whose details say it reads back
    assert unreadable == {0x0E, 0x0F, 0x11, 0x13, 0x15, 0x17, 0x21}
    assert dyn5.instance("torque_command").readable
    assert [i.number for i in dyn5.INSTANCES if i.write_error] == [0x14]
    assert dyn5.UNREADABLE == 74565


def test_parameter_instances_name_drive_parameters() -> None:
    prs = {i.number: (i.param, i.pr) for i in dyn5.INSTANCES if i.kind is dyn5.Kind.PARAMETER}
    assert prs == {0x04: ("main_gain", 0), 0x05: ("speed_gain", 1), 0x06: ("int_gain", 2),
                   0x07: ("trq_cons", 3), 0x08: ("max_speed", 7), 0x09: ("max_accel", 11),
                   0x0A: ("on_range", 15), 0x0B: ("gear_num", 19), 0x0C: ("line_num", 20),
                   0x20: ("torque_limit", 4)}
    for name, _ in prs.values():
        assert name is not None and name in P.BY_NAME


def test_quirk_constants() -> None:
    assert (dyn5.ENABLE, dyn5.DISABLE) == (43690, 57054)
    assert (dyn5.RESET_KEY, dyn5.ORIGIN_KEY) == (43981, 65535)
    assert dyn5.ERROR_STATUS == 0x05 and dyn5.WRITE_SIZE == 4
    assert dyn5.MIN_RPI_US == 5000
    assert (dyn5.INPUT_ASSEMBLY, dyn5.OUTPUT_ASSEMBLY) == (100, 101)


def test_identity_values_of_section_4_2() -> None:
    i = dyn5.IDENTITY
    assert (i.vendor_id, i.device_type, i.product_code, i.status, i.serial_number) == (
        0xABCD, 127, 1, 0, 1)
    assert i.vendor_id == 43981  # the PLC example's VendorID tag
    assert i.product_name == "DYN5ENIP" and len(i.product_name) == 8


def test_check_names_the_range() -> None:
    with pytest.raises(ArgumentRangeError, match=r"0\.\.63"):
        dyn5.instance("memory_test").check(64)
    with pytest.raises(ArgumentRangeError, match="read-only"):
        dyn5.instance("motor_speed").check(1)
    with pytest.raises(ArgumentRangeError, match="0xAAAA or 0xDEDE"):
        dyn5.instance(0x0D).check(1)
    with pytest.raises(ArgumentRangeError):
        dyn5.instance("nope")
    assert dyn5.instance("gear_num").check(16384) == 16384


def test_torque_examples_of_section_4_4() -> None:
    # 0x1F: 0xFF63 = -157 on a 20 A drive -> 1.57 A; x 0.755 N m/A = 1.19 N m (CW: negative)
    inst = dyn5.instance("motor_torque")
    assert inst.decode(bytes.fromhex("63ffffff")) == -157
    amps = dyn5.torque_to_amps(-157, 20.0)
    assert round(abs(amps), 2) == 1.57 and amps < 0
    assert round(abs(amps) * 0.755, 2) == 1.19
    # 0x26: 150 on a 20 A drive -> 1.5 A; x 0.568 N m/A = 0.852 N m
    assert dyn5.torque_to_amps(150, 20.0) == pytest.approx(1.5)
    assert dyn5.torque_to_amps(150, 20.0) * 0.568 == pytest.approx(0.852)
    assert dyn5.amps_to_torque(20.0, 20.0) == 2000 and dyn5.amps_to_torque(-99, 20.0) == -2000


def test_torque_limit_table_of_section_4_4() -> None:
    # DYN5-H01 (20 A peak): 127 -> 20 A, 64 -> 10 A, 10 -> 1.57 A
    assert dyn5.torque_limit_amps(127, 20.0) == 20.0
    assert round(dyn5.torque_limit_amps(64, 20.0)) == 10
    assert round(dyn5.torque_limit_amps(10, 20.0), 2) == 1.57


def test_position_wraps_at_28_bits() -> None:
    top = 134_217_727
    assert dyn5.wrap_position(top) == top
    assert dyn5.wrap_position(top + 1) == -134_217_728
    assert dyn5.wrap_position(-134_217_729) == top
    assert dyn5.wrap_position(2_895_232) == 2_895_232


@given(st.integers(-(1 << 31), (1 << 32) - 1))
def test_udint_round_trip(value: int) -> None:
    raw = dyn5.encode_udint(value)
    assert len(raw) == 4
    assert dyn5.decode_udint(raw) == value & 0xFFFF_FFFF
    assert dyn5.to_signed32(dyn5.decode_udint(raw)) == (value if value < (1 << 31)
                                                         else value - (1 << 32))


@given(st.sampled_from(dyn5.INSTANCES), st.integers(-(1 << 31), (1 << 31) - 1))
def test_instance_encode_decode(inst: dyn5.Instance, value: int) -> None:
    if not inst.signed:
        value &= 0x7FFF_FFFF
    assert inst.decode(inst.encode(value)) == value


def test_udint_rejects_out_of_range() -> None:
    with pytest.raises(ArgumentRangeError):
        dyn5.encode_udint(1 << 32)
    with pytest.raises(ArgumentRangeError):
        dyn5.decode_udint(b"\x00\x00")
