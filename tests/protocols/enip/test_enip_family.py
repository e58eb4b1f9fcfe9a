"""The DMM DYN5 family: parameters in Axis names, status word -> AxisStatus, registration."""

from __future__ import annotations

import pytest

from servobus.axis.capabilities import Capability
from servobus.axis.types import Storage
from servobus.families import FAMILIES, family
from servobus.families.dmm.family import DYN2
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.family import DYN5, PARAM_INSTANCES, Dyn5Status, axis_status


def test_registered_and_counts() -> None:
    assert family("dmm-dyn5") is DYN5
    assert "dmm-dyn5" in FAMILIES
    assert DYN5.counts_per_rev == 65_536  # 16-bit encoder (4.4 0x1D, 6.3)


def test_every_settable_instance_is_a_parameter_in_axis_names() -> None:
    settable = {i.number for i in dyn5.INSTANCES if i.access is dyn5.Access.RW
                and i.kind in (dyn5.Kind.PARAMETER, dyn5.Kind.STORED)}
    assert {i.number for i in PARAM_INSTANCES.values()} == settable
    names = [p.name for p in DYN5.params]
    # the drive parameters keep the DMM names, so backups and `servobus set` mean the same
    assert names[:10] == ["main_gain", "speed_gain", "int_gain", "trq_cons", "max_speed",
                          "max_accel", "on_range", "gear_num", "line_num", "torque_limit"]
    assert set(names[:10]) <= {p.name for p in DYN2.params}
    assert names[10:] == ["memory_test", "torque_speed_limit"]
    assert all(p.storage is Storage.RAM for p in DYN5.params)  # 4.1: writes go to RAM


@pytest.mark.parametrize(("name", "low", "high"), [
    ("gear_num", 1, 16384), ("line_num", 1, 4095), ("torque_limit", 1, 127),
    ("memory_test", 0, 63), ("torque_speed_limit", 1, 20000), ("max_speed", 1, 127)])
def test_ranges_are_the_dyn5_table_s(name: str, low: int, high: int) -> None:
    p = DYN5.param(name)
    assert (p.minimum, p.maximum) == (low, high)
    assert p.check(low) == low and p.check(high) == high
    for bad in (low - 1, high + 1):
        with pytest.raises(ValueError):
            p.check(bad)


def test_status_word_of_the_6_3_example_is_all_normal() -> None:
    st = axis_status(0)  # input1(4) = 0: "servo drive Status is all normal"
    assert st.enabled and st.in_position and not st.moving and not st.alarm
    assert st.family == "dmm-dyn5" and st.raw == 0


@pytest.mark.parametrize(("word", "enabled", "moving", "in_position"), [
    (0x01, True, False, False), (0x02, False, False, True), (0x20, True, True, False),
    (0x23, False, True, False)])
def test_status_bits(word: int, enabled: bool, moving: bool, in_position: bool) -> None:
    st = axis_status(word)  # busy and on position: moving, so not in position (motion_state)
    assert (st.enabled, st.moving, st.in_position) == (enabled, moving, in_position)
    assert st.vendor == Dyn5Status.from_word(word)


@pytest.mark.parametrize(("code", "text", "latched"), [
    (1, "lost phase", True), (2, "over current", True), (3, "overheat", True),
    (4, "CRC", False), (5, "over voltage", True), (6, "alarm 6", True), (7, "alarm 7", True)])
def test_alarm_codes_b4_b2(code: int, text: str, latched: bool) -> None:
    st = axis_status(code << 2 | 0x02)
    assert st.alarm_code == code and text in st.alarm_text
    assert st.alarm_latched is latched
    assert st.vendor.as_dict()["alarm"] == code


def test_capabilities() -> None:
    for capability in (Capability.WAVES, Capability.ORIGIN, Capability.RESET,
                       Capability.TORQUE_MODE, Capability.CYCLIC_IO):
        DYN5.require(capability)
    for missing in (Capability.CONFIG, Capability.DRIVE_ID):
        with pytest.raises(Exception, match="DYN5"):
            DYN5.require(missing)
