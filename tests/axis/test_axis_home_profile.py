"""Issue 32: the Axis's ``home()``, ``set_move_profile()`` and ``following_error()`` on
every family, against the in-process virtual drives.

``home()``: DMM DYN2/DYN4 in absolute mode return to the zero stored by Set_Origin after a
power-on reset (the drive's own homing); in relative mode, and on the DYN5 and YZ-AIM, it
is NotSupported saying why, with nothing sent. ``set_move_profile()`` writes the family's
profile parameters only where the drive differs. ``following_error()`` is the virtual
drives' own (no family reports one on its wire: None there).
"""

from __future__ import annotations

import math

import pytest

from servobus.axis import Axis, connect
from servobus.errors import ArgumentRangeError, MoveFailed, NotSupported
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import DriveConfig, ServoMode
from servobus.transport.base import Direction

URLS = ["sim://dyn232?fast=1", "sim://dyncan?fast=1", "sim://enip", "sim://easycan?fast=1",
        "sim://modbus?fast=1"]
WHY_NOT = {"dmm-dyn2": r"relative mode \(config b2 = 0\)",
           "dmm-dyn5": "runs no homing of its own",
           "yzaim": "homes only by itself at power-on"}


@pytest.fixture(params=URLS)
def axis(request: pytest.FixtureRequest) -> Axis:
    ax = connect(request.param, drive_id=1)
    request.addfinalizer(ax.close)
    return ax


def test_home_says_why_where_the_drive_has_none_and_sends_nothing(axis: Axis) -> None:
    sent: list[object] = []
    axis.add_trace(lambda direction, packet, t: sent.append((direction, packet)))
    before = axis.position()
    reads = len(sent)
    with pytest.raises(NotSupported, match=WHY_NOT[axis.family.name]) as info:
        axis.home()
    assert info.value.family == axis.family.name and "origin" in str(info.value)
    if axis.family.name != "dmm-dyn2":  # the DMM drive reads its config to tell: no write
        assert len(sent) == reads
    assert axis.position() == before


@pytest.mark.parametrize("url", ["sim://dyn232?fast=1", "sim://dyncan?fast=1"])
def test_a_dmm_drive_in_absolute_mode_homes_to_its_stored_zero(url: str) -> None:
    with connect(url, drive_id=1) as axis:
        axis.extra.set_config(DriveConfig(absolute=True))
        axis.set_origin()  # the zero it stores
        axis.move_by(axis.revs(0.3), wait=True)
        assert axis.position() > axis.revs(0.29)
        axis.home()
        status = axis.wait_idle(10)
        assert status.idle and abs(axis.position()) <= axis.position_window()


@pytest.mark.parametrize(("url", "asked", "expected"), [
    ("sim://dyn232?fast=1", (600.0, 6000.0), {"max_speed": 26, "max_accel": 9}),
    ("sim://enip", (600.0, 6000.0), {"max_speed": 26, "max_accel": 9}),
    ("sim://easycan?fast=1", (600.0, 6000.0), {"target_speed": 600, "acceleration": 6000}),
    ("sim://modbus?fast=1", (90.5, None), {"target_speed": 91}),
])
def test_the_move_profile_is_written_only_where_the_drive_differs(
        url: str, asked: tuple[float, float | None], expected: dict[str, int]) -> None:
    with connect(url, drive_id=1) as axis:
        assert axis.set_move_profile(*asked) == expected
        assert axis.read_params(list(expected)) == expected
        assert axis.set_move_profile(*asked) == {}  # the drive has them now: nothing written


def test_the_dmm_profile_runs_at_least_the_speed_and_at_most_the_acceleration() -> None:
    for rpm in (1.0, 100.0, 600.0, 1985.0, 3000.0):
        v = U.profile_params(rpm, None, 4096)["max_speed"]
        assert U.profile_speed_rpm(v) >= rpm
        assert v == 1 or U.profile_speed_rpm(v - 1) < rpm
    for accel in (10.0, 6000.0, 19073.4, 1e6):
        a = U.profile_params(None, accel, 4096)["max_accel"]
        assert 1 <= a <= 127
        assert a == 1 or U.profile_accel_rpm_s(a) <= accel
        assert a == 127 or U.profile_accel_rpm_s(a + 1) > accel
    # At GEAR_NUM 1024 each command unit is 4x the motion: (12+3)^2/16 x 12.21 x 4 = 687 rpm
    assert U.profile_params(600.0, None, 1024) == {"max_speed": 12}
    with pytest.raises(ArgumentRangeError, match="above the fastest profile"):
        U.profile_params(U.profile_speed_rpm(127) + 1, None, 4096)


def test_a_move_profile_value_is_checked_before_anything_is_sent(axis: Axis) -> None:
    for bad in (0, -5.0, math.nan, math.inf):
        with pytest.raises(ArgumentRangeError):
            axis.set_move_profile(bad)


def test_the_following_error_is_the_virtual_drives_own(axis: Axis) -> None:
    error = axis.following_error()
    if axis.family.name.startswith("dmm-"):  # DMM virtual drives report their Pset - Pmotor
        assert isinstance(error, float) and abs(error) < axis.position_window()
    else:  # YZ-AIM: no register holds it, and its virtual motor keeps no such state
        assert error is None


@pytest.mark.parametrize("config", [DriveConfig(absolute=True, free=True),
                                    DriveConfig(absolute=True, servo_mode=ServoMode.SPEED)])
def test_a_dmm_drive_that_would_not_home_is_refused_before_the_reset(config: DriveConfig
                                                                     ) -> None:
    with connect("sim://dyn232?fast=1", drive_id=1) as axis:
        axis.extra.set_config(config)
        sent: list[object] = []
        axis.add_trace(lambda d, packet, t: sent.append(packet) if d is Direction.TX else None)
        with pytest.raises(MoveFailed, match="would not home: its config starts it"):
            axis.home()
        assert len(sent) == 1  # the config read, and no reset
