"""One Axis contract, run against every protocol's virtual drive (like python-can's
back-to-back tests): the same calls, the same units, the same errors on every protocol.

A protocol joins through its ProtocolSpec in the registry (CONTRACT_URLS).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from rig import wait_until

from servobus.axis import Axis, connect, registry
from servobus.axis.capabilities import Capability
from servobus.axis.capture import STATUS_BITS
from servobus.axis.types import AxisStatus
from servobus.errors import ArgumentRangeError, DriveTimeout, NotSupported

#: Every protocol's in-process virtual drive, one drive with id DRIVE: from the registry,
#: so a protocol whose ProtocolSpec names a ``sim`` is in the contract (``fast=1`` drops the
#: wire pacing; every sim:// accepts it, EtherNet/IP has none to drop).
CONTRACT_URLS = [f"sim://{spec.name}?fast=1" for spec in registry.specs().values() if spec.sim]
DRIVE = 1
ABSENT = 9

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(params=CONTRACT_URLS)
def axis(request: pytest.FixtureRequest) -> Iterator[Axis]:
    with connect(request.param, drive_id=DRIVE, timeout=0.2) as ax:
        yield ax


def test_identity_and_units(axis: Axis) -> None:
    assert axis.drive_id == DRIVE and DRIVE in axis.drive_ids
    assert isinstance(axis.protocol, str) and axis.protocol
    assert axis.counts_per_rev == axis.family.counts_per_rev > 0
    assert axis.revs(1) == axis.counts_per_rev
    assert axis.degrees(-90) == -axis.counts_per_rev // 4


def test_status_is_one_axis_status(axis: Axis) -> None:
    st = axis.status()
    assert isinstance(st, AxisStatus)
    assert st.enabled and st.in_position and not st.moving
    assert st.alarm_code == 0 and st.alarm_text == "" and not st.alarm
    assert st.family == axis.family.name


def test_move_in_counts_and_back(axis: Axis) -> None:
    start = axis.position()
    window = axis.position_window()
    quarter = axis.revs(0.25)
    axis.move_by(quarter, wait=True, timeout=10)
    assert abs(axis.position() - (start + quarter)) <= window
    axis.move_to(start, wait=True, timeout=10, confirm=True)
    assert abs(axis.position() - start) <= window


def test_speed_in_rpm_then_stop(axis: Axis) -> None:
    axis.turn(300)
    wait_until(lambda: abs(axis.speed() - 300) <= 15, timeout=5, what="300 rpm")
    assert math.isfinite(axis.current())
    axis.stop()
    wait_until(lambda: abs(axis.speed()) <= 5, timeout=5, what="standstill")


def test_a_streamed_target_retargets_and_the_drive_rests_at_the_last(axis: Axis) -> None:
    """A lease's primitive (issue 27): each stream_to moves the running target; with no
    update after the last, the drive comes to rest there by itself."""
    profile = axis.stream_profile()
    assert profile.max_rpm > 0 and profile.accel_rpm_s > 0
    start = axis.position()
    window = axis.position_window()
    step = axis.revs(0.1)
    for k in range(1, 4):
        axis.stream_to(start + k * step, 120)
    wait_until(lambda: axis.status().idle, timeout=10, what="at rest at the last target")
    assert abs(axis.position() - (start + 3 * step)) <= window
    with pytest.raises(ArgumentRangeError):
        axis.stream_to(start, 0)


def test_parameters_read_write_and_range(axis: Axis) -> None:
    params = axis.parameters()
    assert params
    values = axis.read_params()
    assert list(values) == [p.name for p in params]
    p = next(p for p in params if p.maximum > p.minimum + 1 and p.name != "gear_num")
    new = p.minimum + 1 if values[p.name] != p.minimum + 1 else p.minimum
    axis.write_param(p.name, new)
    assert axis.read_param(p.name) == new
    with pytest.raises(ArgumentRangeError):
        axis.write_param(p.name, p.maximum + 1)
    with pytest.raises(ArgumentRangeError):
        axis.write_params({p.name: values[p.name], "no_such_parameter": 1})
    assert axis.read_param(p.name) == new  # nothing of the refused batch was written


@pytest.mark.parametrize("bad", [None, 1.5, math.nan, "10", True])
def test_bad_arguments_are_refused_before_sending(axis: Axis, bad: object) -> None:
    before = axis.position()
    with pytest.raises(ArgumentRangeError):
        axis.move_to(bad)
    with pytest.raises(ArgumentRangeError):
        axis.move_by(bad)
    assert abs(axis.position() - before) <= axis.position_window()


def test_unknown_parameter_and_missing_feature(axis: Axis) -> None:
    with pytest.raises(ArgumentRangeError):
        axis.read_param("no_such_parameter")
    missing = next(c for c in Capability if not axis.supports(c))
    with pytest.raises(NotSupported) as info:
        axis.require(missing)
    assert info.value.family == axis.family.name


def test_an_absent_drive_times_out_typed(axis: Axis) -> None:
    ghost = axis.sibling(ABSENT)
    assert ghost.ping(timeout=0.05) is False
    with pytest.raises(DriveTimeout):
        ghost.position()
    assert axis.ping(timeout=0.5) is True  # the connection is still fine


def test_waves_exist_or_are_not_supported(axis: Axis) -> None:
    """A feature is there when the family has it, else NotSupported names the family."""
    if axis.supports(Capability.WAVES):
        axis.wave_frequency(0)  # stops any wave: harmless
    else:
        with pytest.raises(NotSupported):
            axis.square_wave(100)


def test_moving_and_in_position_mean_the_same_everywhere(axis: Axis) -> None:
    """moving: the motor turns or a profile runs; in_position: on target and still
    (docs/axis.md "Moving and in position"): at rest, in constant speed, during a move."""
    def at_rest() -> None:
        # wait_idle: idle that holds (a single idle read can be a zero crossing of the
        # servo's ring after a stop, docs/axis.md); then a read of its own says so too
        axis.wait_idle(timeout=5)
        st = axis.status()
        assert not st.moving and st.in_position and st.idle, st

    at_rest()
    axis.turn(600)
    wait_until(lambda: abs(axis.speed() - 600) <= 30, timeout=5, what="600 rpm")
    st = axis.status()
    assert st.moving and not st.in_position and not st.idle, st
    axis.stop()
    at_rest()

    target = axis.position() + axis.revs(40)
    axis.move_to(target)
    wait_until(lambda: abs(axis.speed()) >= 100, timeout=5, what="the move under way")
    st = axis.status()
    # the position read after the status is still short of the target: the status was
    # taken during the move
    assert abs(axis.position() - target) > 10 * axis.position_window()
    assert st.moving and not st.in_position and not st.idle, st
    axis.wait_idle(timeout=30)
    at_rest()


def test_a_drive_trace_has_the_same_moving_and_in_position(axis: Axis) -> None:
    """The scope's status bits (trace_buffer) follow the AxisStatus meaning too."""
    try:
        axis.trace_buffer()  # starts the recording
    except NotSupported:
        pytest.skip(f"{axis.protocol} keeps no drive trace")
    axis.turn(600)
    wait_until(lambda: abs(axis.speed() - 600) <= 30, timeout=5, what="600 rpm")
    axis.trace_buffer()  # drop the samples of the ramp
    samples: list[float] = []
    wait_until(lambda: samples.extend(axis.trace_buffer().signals["status"]) or bool(samples),
               timeout=5, what="trace samples at constant speed")
    bits = int(samples[-1])
    moving, in_position = bits >> STATUS_BITS.index("moving") & 1, \
        bits >> STATUS_BITS.index("in_position") & 1
    assert (moving, in_position) == (1, 0)
    axis.stop()


def test_a_move_out_of_reach_is_refused_in_counts(axis: Axis) -> None:
    """The range of a move is in counts on every protocol (move_range), and so is the error."""
    for relative in (False, True):
        limits = axis.move_range(relative=relative)
        assert limits is not None
        low, high = limits
        assert low < 0 < axis.revs(100) < high
        with pytest.raises(ArgumentRangeError, match=f"{high + 1} counts is outside "
                                                     f"{low}..{high} counts"):
            (axis.move_by if relative else axis.move_to)(high + 1)
