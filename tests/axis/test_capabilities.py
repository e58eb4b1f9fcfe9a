"""Typed capabilities (issue 31, servobus.axis.capabilities): what each protocol's virtual
drive says it can do, the typed error for what it cannot, and that every declaration
matches the code (a capability with a method is declared exactly where the method is
implemented)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from servobus.axis import AsyncAxis, Axis, Capability, connect
from servobus.axis.capabilities import CONNECTION_CAPABILITIES
from servobus.axis.types import Family
from servobus.errors import NotSupported
from servobus.families.dmm.family import DYN2
from servobus.families.dyn5.family import DYN5
from servobus.families.yzaim.family import YZAIM
from servobus.link.stats import TransactionStats

pytestmark = pytest.mark.timeout(60)

C = Capability
#: What every in-process virtual drive has: a trace the host reads, a client that counts.
VIRTUAL = {C.DRIVE_TRACE, C.LINK_STATS}
#: The DMM profile (dyn232, dyncan, enip) on any protocol.
DMM = {C.ORIGIN, C.RESET, C.WAVES, C.COMMAND_UNITS, C.STREAM_TARGETS, C.TUNING}
#: A DYN2/DYN4 homes by itself (absolute-encoder homing); a DYN5 and a YZ-AIM run none.
#: The YZ-AIM profile (easycan, modbus) on any protocol.
YZ = {C.ORIGIN, C.RESET, C.DRIVE_ID, C.STREAM_TARGETS, C.TUNING}

EXPECTED: dict[str, set[Capability]] = {
    # a DYN2 on a serial line: no broadcast start; the virtual DMM drives have JP3 I/O
    "dyn232": DMM | VIRTUAL | {C.CONFIG, C.DRIVE_ID, C.VIRTUAL_IO, C.HOMING},
    # the same drive on CAN: Sync_Trigger is a broadcast
    "dyncan": DMM | VIRTUAL | {C.CONFIG, C.DRIVE_ID, C.VIRTUAL_IO, C.SYNC_START, C.HOMING},
    # a DYN5: no config byte, addressed by IP; torque mode, cyclic I/O, a power marker
    "enip": DMM | VIRTUAL | {C.VIRTUAL_IO, C.TORQUE_MODE, C.CYCLIC_IO,
                             C.POWER_LOSS_DETECTION},
    # YZ-AIM over EasyCan: the position caches start together
    "easycan": YZ | VIRTUAL | {C.SYNC_START, C.CYCLIC_POSITION, C.CYCLIC_GROUP},
    "modbus": YZ | VIRTUAL,
}


@pytest.fixture(params=sorted(EXPECTED))
def axis(request: pytest.FixtureRequest) -> Iterator[Axis]:
    with connect(f"sim://{request.param}?fast=1", drive_id=1, timeout=0.2) as ax:
        yield ax


def test_each_protocol_declares_what_its_drive_can_do(axis: Axis) -> None:
    assert axis.capabilities == EXPECTED[axis.protocol]
    assert all(axis.supports(c) for c in EXPECTED[axis.protocol])


def test_a_missing_capability_is_a_typed_error_naming_the_family(axis: Axis) -> None:
    missing = set(Capability) - axis.capabilities
    assert missing
    for capability in missing:
        assert not axis.supports(capability)
        with pytest.raises(NotSupported, match=capability.words) as info:
            axis.require(capability)
        assert info.value.family == axis.family.name


def test_the_typed_calls_of_a_missing_capability_raise_before_sending(axis: Axis) -> None:
    if not axis.supports(C.SYNC_START):
        with pytest.raises(NotSupported, match="sync start"):
            axis.sync_move_to([(axis, 0)])
    if not axis.supports(C.WAVES):
        with pytest.raises(NotSupported, match="waves"):
            axis.square_wave(100)
    if not axis.supports(C.HOMING):
        with pytest.raises(NotSupported):  # the family's own words why
            axis.home()
    if not axis.supports(C.STREAM_TARGETS):
        with pytest.raises(NotSupported, match="stream"):
            axis.stream_profile()
    if not axis.supports(C.POWER_LOSS_DETECTION):
        assert axis.power_marker() is None
    if not axis.supports(C.CYCLIC_POSITION):
        with pytest.raises(NotSupported, match="cyclic position"):
            axis.stream_cycles(lambda: 0)
    assert axis.position() is not None  # the link is fine: nothing half-sent


def test_link_statistics_count_the_calls(axis: Axis) -> None:
    axis.status()
    stats = axis.link_stats()
    assert isinstance(stats, TransactionStats) and stats.sent > 0


@pytest.mark.parametrize("family", [DYN2, DYN5, YZAIM], ids=lambda f: f.name)
def test_a_family_declares_no_connection_capability(family: Family) -> None:
    assert family.capabilities and not family.capabilities & CONNECTION_CAPABILITIES


#: A capability that is a method of AsyncAxis: declared exactly where it is implemented.
METHODS = {C.HOMING: "home", C.WAVES: "square_wave", C.STREAM_TARGETS: "stream_profile",
           C.POWER_LOSS_DETECTION: "power_marker", C.CYCLIC_POSITION: "stream_cycles",
           C.CYCLIC_GROUP: "stream_cycles_together"}


def test_a_declared_capability_is_implemented(axis: Axis) -> None:
    """A declared capability has its method implemented; the other way round (implemented,
    not declared) the call above would not raise (a family may override a method only to
    say why it has not the capability: DYN5 and YZ-AIM ``home()``)."""
    core = type(axis.core)
    for capability, name in METHODS.items():
        if axis.supports(capability):
            assert getattr(core, name) is not getattr(AsyncAxis, name), (capability, name)
    assert callable(getattr(core, "move_to_command", None)) == axis.supports(C.COMMAND_UNITS)
