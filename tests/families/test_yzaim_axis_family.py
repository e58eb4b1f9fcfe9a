"""The YZ-AIM Family object: registry entry, parameters, alarms, AxisStatus decoding."""

from __future__ import annotations

import pytest

from servobus.axis.capabilities import Capability
from servobus.axis.types import Storage
from servobus.errors import ArgumentRangeError, NotSupported
from servobus.families import family
from servobus.families.yzaim import registers as Y
from servobus.families.yzaim.family import YZAIM, axis_status


def test_registered_as_yzaim_with_32768_counts() -> None:
    assert family("yzaim") is YZAIM
    assert YZAIM.counts_per_rev == 32768
    assert YZAIM.revs_to_counts(2) == 65536  # 5.4a: two turns
    assert YZAIM.degrees_to_counts(36) == round(32768 / 10)  # 4.6: 36 deg


def test_parameters_are_the_settings_in_raw_register_units() -> None:
    names = [p.name for p in YZAIM.params]
    assert names[:2] == ["target_speed", "acceleration"]
    for gone in ("modbus_enable", "output_enable", "device_address", "save_flag",
                 "sync_control", "absolute_position_low", "position_cache_high", "alarm_code"):
        assert gone not in names
    speed = YZAIM.param("target_speed")
    assert (speed.minimum, speed.maximum, speed.default, speed.unit) == (0, 3000, 1000, "rpm")
    assert YZAIM.param("max_current").unit.startswith("mA")
    assert all(p.storage is Storage.RAM for p in YZAIM.params)  # saved only by 0x14
    with pytest.raises(ArgumentRangeError):
        speed.check(3001)
    with pytest.raises(ArgumentRangeError):
        YZAIM.param("max_speed")


def test_alarm_texts_and_features() -> None:
    assert YZAIM.alarm_text(0) == ""
    assert "stall" in YZAIM.alarm_text(0x14)
    assert YZAIM.alarm_text(0x33) == "alarm 51"
    YZAIM.require(Capability.ORIGIN)
    with pytest.raises(NotSupported):
        YZAIM.require(Capability.WAVES)


def test_status_idle_moving_and_alarms() -> None:
    idle = axis_status(1, 0, 0)
    assert idle.enabled and idle.idle and not idle.alarm and idle.family == "yzaim"
    turning = axis_status(1, 0, (-3000) & 0xFFFF)  # -300.0 rpm
    assert turning.moving and not turning.idle and turning.vendor.speed_rpm == -300.0
    short = axis_status(1, 0, 0, position_error=11)  # 5.4a: +-10 counts
    assert short.moving and not short.in_position
    there = axis_status(1, 0, 5, position_error=-10)  # 0.5 rpm, 10 counts off
    assert there.idle
    stall = axis_status(1, 0x14, 0)
    assert stall.alarm_latched and not stall.enabled and stall.alarm_code == 0x14
    battery = axis_status(1, 0x13, 0)
    assert battery.alarm and not battery.alarm_latched and battery.enabled
    assert not axis_status(0, 0, 0).enabled
    assert Y.POSITION_TOLERANCE_COUNTS == 10
