"""YZ-AIM family: register table sanity, unit conversions, golden figures of the manual.

Golden figures (YZ-AIM EasyCan v3.5 manual):
  3.2  3200 pulses/rev -> gear 256:25; 8192 pulses/rev (default) -> 4:1;
       1000 rpm at 8192 pulses/rev -> 136533 Hz
  5.4a incremental 32768 = words 00 80 / 00 00 (0x8000, 0x0000); -32768 = 00 80 FF FF;
       absolute 00 00 01 00 = 65536 (2 turns); reply 0E 37 00 00 = 0x370E
  5.4c 600 rpm -> 655.36 counts per 2 ms cycle
  1    57AIM30C: 0.96 N*m, rated 1000 rpm, max 1500 rpm (every model of the tables)
"""

from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ArgumentRangeError
from servobus.families.yzaim import registers as Y

# ------------------------------------------------------------------ table sanity


def test_every_address_once_in_order() -> None:
    assert [r.address for r in Y.REGISTERS] == list(range(0x1E))
    assert Y.REGISTER_COUNT == 0x1E
    assert len(Y.BY_NAME) == len(Y.REGISTERS)  # names unique
    assert not set(Y.BY_NAME) & set(Y.PAIR_BY_NAME)


def test_names_are_snake_case() -> None:
    for name in [*Y.BY_NAME, *Y.PAIR_BY_NAME]:
        assert re.fullmatch(r"[a-z][a-z0-9]*(_[a-z0-9]+)*", name), name


@pytest.mark.parametrize("reg", Y.REGISTERS, ids=lambda r: r.name)
def test_register_ranges_consistent(reg: Y.Register) -> None:
    assert reg.minimum <= reg.maximum
    assert reg.minimum >= -0x8000 and reg.maximum <= Y.WORD_MAX
    if reg.signed:
        assert reg.maximum <= 0x7FFF
    assert reg.per_unit > 0
    assert all(reg.minimum <= v <= reg.maximum for v in reg.invalid)
    if reg.access is Y.Access.R:
        assert reg.default is None and not reg.saved
    else:
        assert reg.default is not None and reg.valid(reg.default)
    assert reg.doc


def test_pairs_low_word_at_lower_address() -> None:
    assert [(p.name, p.low, p.high) for p in Y.PAIRS] == [
        ("incremental_position", 0x0C, 0x0D),
        ("absolute_position", 0x16, 0x17),
        ("position_cache", 0x1A, 0x1B),
    ]
    for p in Y.PAIRS:
        low, high = Y.register(p.low), Y.register(p.high)
        assert (low.name, high.name) == (f"{p.name}_low", f"{p.name}_high")
        assert low.access is high.access
        assert (low.minimum, low.maximum) == (high.minimum, high.maximum) == (0, Y.WORD_MAX)
        assert (p.minimum, p.maximum) == (-(2**31), 2**31 - 1)
        assert not low.saved and not high.saved


def test_saved_registers() -> None:
    assert {r.address for r in Y.SAVED} == {*range(0x02, 0x0C), 0x15, 0x18, 0x19, 0x1D}


def test_manual_scales_and_ranges() -> None:
    r = Y.register
    assert Y.COUNTS_PER_REV == 32768
    assert r("system_current").to_engineering(2000) == 1.0
    assert r("motor_speed").to_engineering(-15000) == -1500.0
    assert r("supply_voltage").to_engineering(327 * 24) == 24.0
    assert r("speed_feedforward").to_engineering(327) == 1.0
    assert r("speed_loop_kp").to_engineering(10000) == 10.0
    assert r("standstill_max_output").to_engineering(609) == pytest.approx(60.9)
    assert r("max_current").to_engineering(10009) == pytest.approx(10.009)
    assert r("output_pwm").to_engineering(32767) == pytest.approx(100.0)
    assert (r(0x10).minimum, r(0x10).maximum) == (-30000, 30000)
    assert (r(0x02).maximum, r(0x03).maximum, r(0x06).minimum, r(0x06).maximum) == (
        3000, 65535, 2, 2000)
    assert (r(0x07).minimum, r(0x07).maximum, r(0x0B).minimum) == (60, 30000, 1)
    assert r(0x0E).access is Y.Access.R and r(0x14).access is Y.Access.ACTION


# ------------------------------------------------------------------ range checks


@pytest.mark.parametrize("reg", Y.REGISTERS, ids=lambda r: r.name)
def test_range_edges(reg: Y.Register) -> None:
    assert reg.check(reg.minimum) == reg.minimum
    assert reg.check(reg.maximum) == reg.maximum
    for bad in (reg.minimum - 1, reg.maximum + 1):
        with pytest.raises(ArgumentRangeError, match=reg.name):
            reg.check(bad)
    with pytest.raises(ArgumentRangeError):
        reg.check(True)


def test_invalid_and_read_only_refused() -> None:
    with pytest.raises(ArgumentRangeError, match="except 5"):
        Y.register("special_function").check(5)
    with pytest.raises(ArgumentRangeError, match="read-only"):
        Y.encode_parameter("motor_speed", 0)
    with pytest.raises(ArgumentRangeError, match="device_address"):
        Y.encode_parameter("device_address", 0xFF)  # the host's own EasyCan address
    with pytest.raises(ArgumentRangeError):
        Y.encode_parameter("absolute_position", 2**31)
    with pytest.raises(ArgumentRangeError, match="unknown YZ-AIM register 0x1E"):
        Y.register(0x1E)
    with pytest.raises(ArgumentRangeError, match="unknown YZ-AIM parameter"):
        Y.parameter("max_speed")
    with pytest.raises(ArgumentRangeError):
        Y.decode_parameter("absolute_position", (1,))
    with pytest.raises(ArgumentRangeError):
        Y.register("motor_speed").from_word(0x10000)


# ------------------------------------------------------------------ golden figures


def test_gear_examples() -> None:
    assert Y.gear_for_pulses_per_rev(3200) == (256, 25)
    assert Y.gear_for_pulses_per_rev(8192) == (4, 1)
    assert Y.pulses_per_rev(4, 1) == 8192
    assert Y.pulses_per_rev(256, 25) == 3200
    assert (Y.register("gear_numerator").default, Y.register("gear_denominator").default) == (
        4, 1)
    assert int(Y.pulse_frequency_hz(1000, 8192)) == 136533
    assert Y.pulses_to_counts(8192, 4, 1) == Y.COUNTS_PER_REV
    with pytest.raises(ArgumentRangeError):
        Y.pulses_per_rev(0, 1)


def test_word_examples() -> None:
    assert Y.encode_parameter("incremental_position", 32768) == (0x0C, (0x8000, 0x0000))
    assert Y.encode_parameter("incremental_position", -32768) == (0x0C, (0x8000, 0xFFFF))
    assert Y.decode_parameter("absolute_position", (0x0000, 0x0001)) == 65536  # 2 turns
    assert Y.join32(0x370E, 0x0000) == 0x370E
    assert Y.join32(0x3711, 0) == 0x370E + 3
    assert Y.encode_parameter("special_function", 0) == (0x19, (0,))
    assert Y.encode_parameter("save_flag", 1) == (0x14, (1,))
    assert Y.encode_parameter("target_speed", 1000) == (0x02, (0x03E8,))
    assert Y.encode_parameter("acceleration", 10000) == (0x03, (0x2710,))


def test_cycle_and_angles() -> None:
    assert Y.counts_per_cycle(600) == pytest.approx(655.36)
    assert Y.SYNC_CYCLE_S == 0.002
    assert Y.power_on_angle_deg(32768) == 360.0
    assert Y.counts_to_deg(Y.deg_to_counts(36.0)) == pytest.approx(36.0)


def test_units_digits() -> None:
    assert Y.stall_alarm_seconds(609) == 9
    assert Y.stall_alarm_seconds(600) is None
    assert Y.over_current_alarm_seconds(10009) == 9
    assert Y.over_current_alarm_seconds(5000) is None
    assert Y.pulse_polarity_at_turn_on(1001) and not Y.pulse_polarity_at_turn_on(1000)
    assert Y.alarm_output_normally_closed(1501)
    assert not Y.alarm_output_normally_closed(1500)
    assert Y.uses_internal_profile(59999) and not Y.uses_internal_profile(60000)


def test_special_functions() -> None:
    assert {int(f) for f in Y.SpecialFunction} == {0, 1, 2, 3, 4, 6, 7, 8, 9}
    assert set(Y.SPECIAL_FUNCTION_TEXTS) == set(Y.SpecialFunction)
    assert "speed mode" in Y.special_function_text(3)
    assert "180.00 deg" in Y.special_function_text(16384)
    assert "undefined" in Y.special_function_text(5)
    assert Y.speed_mode_rpm(10) == 0 and Y.speed_mode_rpm(90) == 1000
    assert Y.speed_mode_rpm(50) == 500 and Y.speed_mode_rpm(99) == 1000
    assert [int(f) for f in Y.SaveFlag] == [0, 1, 2, 3]


def test_alarms() -> None:
    stall = Y.alarm(0x14)
    assert (stall.name, stall.flashes, stall.stops_motor) == ("stall", (1, 4), True)
    assert Y.alarm(0).name == "none" and not Y.alarm(0).stops_motor
    names = {a.name for a in Y.ALARMS}
    assert {"stall", "over_current", "over_voltage", "battery_warning"} <= names
    assert len(Y.ALARM_BY_CODE) == len(Y.ALARMS)
    assert Y.alarm(0x7E).name == "unknown" and "0x7E" in Y.alarm(0x7E).text


def test_models() -> None:
    m = Y.model("57aim30c")
    assert (m.torque_nm, m.rated_rpm, m.max_rpm, m.power_w, m.current_a) == (
        0.96, 1000, 1500, 100, 4.4)
    assert [x.name for x in Y.MODELS] == [
        "42AIM15C", "42AIM10C", "57AIM15C", "57AIM15CH", "57AIM30C", "57AIM30CH",
        "60AIM25C", "60AIM25CH"]
    for x in Y.MODELS:
        mech_w = x.torque_nm * x.rated_rpm * 2 * 3.14159265 / 60
        assert mech_w == pytest.approx(x.power_w, rel=0.05), x.name  # the tables agree
        assert x.rated_rpm < x.max_rpm <= Y.register("target_speed").maximum
        assert x.supply_v[0] < x.supply_v[1]
        assert x.name.startswith(str(x.frame_mm))
    assert Y.model("60AIM25C").supply_v == (32.4, 39.6)
    assert Y.DEFAULT_MODEL in Y.MODEL_BY_NAME
    with pytest.raises(ArgumentRangeError):
        Y.model("86AIM")


# ------------------------------------------------------------------ properties


@given(st.integers(Y.INT32_MIN, Y.INT32_MAX))
def test_split_join_roundtrip(value: int) -> None:
    low, high = Y.split32(value)
    assert 0 <= low <= Y.WORD_MAX and 0 <= high <= Y.WORD_MAX
    assert Y.join32(low, high) == value


@given(st.integers(0, Y.WORD_MAX), st.integers(0, Y.WORD_MAX))
def test_join_split_roundtrip(low: int, high: int) -> None:
    assert Y.split32(Y.join32(low, high)) == (low, high)


@given(st.data())
def test_register_word_and_engineering_roundtrip(data: st.DataObject) -> None:
    reg = data.draw(st.sampled_from(Y.REGISTERS))
    raw = data.draw(st.integers(reg.minimum, reg.maximum))
    assert reg.from_word(reg.word(raw)) == raw
    assert reg.from_engineering(reg.to_engineering(raw)) == raw


@given(st.data())
def test_parameter_roundtrip(data: st.DataObject) -> None:
    name = data.draw(st.sampled_from(
        [r.name for r in Y.REGISTERS if r.writable] + [p.name for p in Y.PAIRS]))
    p = Y.parameter(name)
    value = data.draw(st.integers(p.minimum, p.maximum).filter(
        lambda v: not isinstance(p, Y.Register) or p.valid(v)))
    address, words = Y.encode_parameter(name, value)
    assert address == (p.low if isinstance(p, Y.Pair) else p.address)
    assert Y.decode_parameter(name, words) == value
