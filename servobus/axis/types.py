"""The Axis API's value types: what every device family gives the vendor-neutral Axis.

:class:`Family` describes a kind of drive, :class:`ParamInfo` one of its parameters,
:class:`AxisStatus` one status, :class:`StreamProfile` how it runs a streamed target
(docs/axis.md). The families (``servobus.families.<f>``) fill them in.

A family is a model of a kind of drive, independent of the
wire: its parameter table (names, ranges, units, RAM/EEPROM), how its status decodes into one
:class:`AxisStatus`, and its counts per revolution. Protocols carry a family's values; the
Axis, the CLI and the GUI read the family to know what a drive has.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

from servobus.axis.capabilities import Capability
from servobus.axis.units import to_counts
from servobus.errors import ArgumentRangeError, NotSupported


class Storage(Enum):
    EEPROM = "eeprom"  # survives reset / power cycle; counts against the EEPROM's endurance
    RAM = "ram"  # lost at reset / power cycle


@dataclass(frozen=True)
class ParamInfo:
    """One settable parameter as the Axis sees it (the family's raw integer units)."""

    name: str  # snake_case: CLI, JSON backups, GUI, Axis API
    minimum: int
    maximum: int
    default: int | None
    unit: str
    storage: Storage
    doc: str

    def check(self, value: object) -> int:
        """``value`` as int if it is an integer in range, else ArgumentRangeError."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise ArgumentRangeError(f"{self.name} must be an integer, got {value!r}")
        if not self.minimum <= value <= self.maximum:
            raise ArgumentRangeError(
                f"{self.name}={value} is outside the allowed range "
                f"{self.minimum}..{self.maximum} ({self.unit})")
        return value


#: At or above this measured speed (rpm, either direction) the motor turns. Below it is the
#: correction of a servo standing on position: the virtual DMM drives read up to 3 rpm for
#: a moment while a move settles, YZ-AIM +-1 rpm (docs/axis.md "Moving and in position").
MOVING_RPM = 5.0


def motion_state(profile_running: bool, on_target: bool,
                 speed_rpm: float | None) -> tuple[bool, bool]:
    """``(moving, in_position)`` as every family defines them (docs/axis.md).

    ``moving``: a profile runs (the drive's busy bit, or a commanded target not reached) or
    the motor turns (``|speed_rpm| >= MOVING_RPM``; None: speed not read because a profile
    already says so). ``in_position``: the drive is on its target (the drive's own
    on-position bit or position comparison) and not moving. So turning at constant speed,
    in a jog, a wave or analog speed mode is moving and never in position, whatever the
    drive's bits say; the bits stay in ``AxisStatus.vendor`` under their own names.
    """
    moving = profile_running or (speed_rpm is not None and abs(speed_rpm) >= MOVING_RPM)
    return moving, on_target and not moving


@dataclass(frozen=True)
class StreamProfile:
    """How a drive runs a streamed position target (a lease, docs/safety.md): its own
    profile's top speed and acceleration, motor rpm and rpm/s. A lease's lead (how far the
    target runs ahead of the motor) is the stopping distance from the asked speed at
    ``accel_rpm_s`` plus one renewal period's travel."""

    max_rpm: float
    accel_rpm_s: float


class VendorStatus(Protocol):
    """A family's own decoded status (``AxisStatus.vendor``): the drive's bits by name."""

    def as_dict(self) -> dict[str, object]: ...


@dataclass(frozen=True)
class AxisStatus:
    """One status for every family; ``vendor`` keeps the family's own decoded value.

    ``moving`` and ``in_position`` mean the same on every protocol (:func:`motion_state`);
    the drive's own bits (``on_position``, ``motion_busy``, ...) are in ``vendor``.
    """

    enabled: bool
    moving: bool
    in_position: bool
    alarm_code: int  # 0 = no alarm; the family's own numbering
    alarm_text: str  # "" when no alarm
    alarm_latched: bool  # holds until reset / power cycle
    raw: int  # the status value as the drive sent it
    family: str
    vendor: VendorStatus | None = field(default=None, compare=False)

    @property
    def alarm(self) -> bool:
        return self.alarm_code != 0

    @property
    def idle(self) -> bool:
        """Motion done and on position (what ``wait_idle`` waits for)."""
        return not self.moving and self.in_position

    def as_dict(self) -> dict[str, object]:
        return {
            "enabled": self.enabled, "moving": self.moving, "in_position": self.in_position,
            "alarm_code": self.alarm_code, "alarm": self.alarm_text,
            "alarm_latched": self.alarm_latched, "raw": self.raw, "family": self.family,
        }


class MoveProfile(Protocol):
    """The figures of one planned point-to-point move, for people and as JSON."""

    def rows(self) -> list[tuple[str, str]]: ...

    def as_dict(self) -> dict[str, float | int]: ...


@dataclass(frozen=True)
class PtpCalculator:
    """A family's point-to-point profile: which of its parameters shape a move (names in
    ``Family.params``), and the calculation from their values and a move's command."""

    inputs: tuple[str, ...]
    compute: Callable[[Mapping[str, int], int], MoveProfile]


class GainRole(Enum):
    """What a tuning gain does in the cascade (docs/tuning.md, "The tuner")."""

    POSITION = "position"  # position loop P (DMM Main Gain, YZ-AIM position kp)
    SPEED = "speed"  # speed loop P (DMM Speed Gain, YZ-AIM speed kp)
    INTEGRAL = "integral"  # speed loop integral (DMM Integration Gain, YZ-AIM Ti)
    FILTER = "filter"  # torque command filter (DMM TrqCons)


class Persistence(Enum):
    """How a gain write persists, which decides what a tuner may write and how it keeps it."""

    #: Every write goes to EEPROM (DMM DYN2/DYN4, manual 5.1): a tuner keeps a write budget.
    EEPROM_EACH_WRITE = "eeprom"
    #: RAM until the family's save command (YZ-AIM save flag 0x14): saved only when asked.
    RAM_SAVE_COMMAND = "save_command"
    #: RAM only over this link (DYN5 over EtherNet/IP): kept with the vendor's tool.
    RAM_ONLY = "ram"


@dataclass(frozen=True)
class TuningGain:
    """One gain of a family's tuning (a name of its parameter table) and how it acts."""

    role: GainRole
    name: str
    #: A larger value acts less (YZ-AIM integration time: longer = less integral).
    inverse: bool = False
    #: The units digit is a configuration bit a tuner must keep (YZ-AIM 0x05, 0x07).
    keep_units_digit: bool = False


@dataclass(frozen=True)
class TuningProfile:
    """What ``Capability.TUNING`` gives a tuner: the gains by role, how writes persist, and
    for people what keeps them where the link cannot (``save_hint``)."""

    gains: tuple[TuningGain, ...]
    persistence: Persistence
    save_hint: str = ""
    #: The drive learns its load and feeds the move's torque forward (DMM Adaptive Tuning,
    #: DYN2 5.2): a softer loop may settle faster there (the tuner's goal "settling").
    learns_load: bool = False

    def gain(self, role: GainRole) -> TuningGain | None:
        return next((g for g in self.gains if g.role is role), None)


@dataclass(frozen=True)
class Family:
    """A device family: name, counts per revolution, parameters, capabilities."""

    name: str  # "dmm-dyn2", "dmm-dyn5", "yzaim"
    title: str  # for people: "DMM DYN2/DYN4"
    counts_per_rev: int
    params: tuple[ParamInfo, ...]
    #: What the family's drives can do beyond the Axis basics, on any protocol
    #: (servobus.axis.capabilities; an Axis adds what its connection gives).
    capabilities: frozenset[Capability] = frozenset()
    #: Alarm code -> text.
    alarms: Mapping[int, str] = field(default_factory=dict)
    #: Motor counts per unit of a drive-generated wave's amplitude (families with "waves"):
    #: a front end checks offset +- amplitude against soft limits before starting one.
    wave_counts_per_unit: float = 0.0
    #: How the family's drives plan a point-to-point move, computed offline from its
    #: parameters (``servobus profile``); None where the family has no such table.
    ptp_profile: PtpCalculator | None = None
    #: The gains a tuner sets (families with ``Capability.TUNING``; servobus.tune).
    tuning: TuningProfile | None = None

    def param(self, name: str) -> ParamInfo:
        for p in self.params:
            if p.name == name:
                return p
        raise ArgumentRangeError(
            f"{self.title} has no parameter {name!r}; it has: "
            f"{', '.join(p.name for p in self.params)}")

    def require(self, capability: Capability) -> None:
        """Raise NotSupported (before anything is sent) when the family lacks ``capability``."""
        if capability not in self.capabilities:
            raise NotSupported(f"{self.title} drives have no {capability.words}",
                               family=self.name)

    def alarm_text(self, code: int) -> str:
        return "" if code == 0 else self.alarms.get(code, f"alarm {code}")

    def revs_to_counts(self, revs: float) -> int:
        return to_counts(revs, "rev", self.counts_per_rev)

    def degrees_to_counts(self, degrees: float) -> int:
        return to_counts(degrees, "deg", self.counts_per_rev)
