"""The one parameter table: id, name, range, unit, storage class, default.

Codecs map their function codes onto these names; the client range-checks against them;
the virtual drive validates writes against them. Nothing else may restate a range.

Defaults are servobus decisions (the manuals give no factory values except GEAR_NUM 4096,
TrqCons "127 in position mode" and the Appendix B example MaxSpd 48 / MaxAcl 30).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from servobus.axis.types import ParamInfo
from servobus.axis.types import Storage as Storage
from servobus.errors import ArgumentRangeError


class ParamId(IntEnum):
    MAIN_GAIN = 0
    SPEED_GAIN = 1
    INT_GAIN = 2
    TRQ_CONS = 3
    MAX_SPEED = 4
    MAX_ACCEL = 5
    ON_RANGE = 6
    GEAR_NUM = 7
    LINE_NUM = 8
    TORQUE_LIMIT = 9


@dataclass(frozen=True)
class ParamSpec:
    id: ParamId
    name: str  # snake_case, used by the CLI, JSON backups and the Axis API
    minimum: int
    maximum: int
    default: int
    unit: str
    storage: Storage
    doc: str

    def check(self, value: int) -> int:
        """Return ``value`` if in range, else raise ArgumentRangeError naming the range."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise ArgumentRangeError(f"{self.name} must be an integer, got {value!r}")
        if not self.minimum <= value <= self.maximum:
            raise ArgumentRangeError(
                f"{self.name}={value} is outside the allowed range "
                f"{self.minimum}..{self.maximum} ({self.unit})"
            )
        return value

    def valid(self, value: int) -> bool:
        return self.minimum <= value <= self.maximum

    @property
    def info(self) -> ParamInfo:
        """The vendor-neutral view the Axis, CLI and GUI use."""
        return ParamInfo(self.name, self.minimum, self.maximum, self.default, self.unit,
                         self.storage, self.doc)


_E, _R = Storage.EEPROM, Storage.RAM

PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec(ParamId.MAIN_GAIN, "main_gain", 1, 127, 40, "-", _E,
              "position loop gain; larger = wider servo bandwidth"),
    ParamSpec(ParamId.SPEED_GAIN, "speed_gain", 1, 127, 40, "-", _E,
              "speed loop gain; larger = narrower bandwidth, for heavier loads"),
    ParamSpec(ParamId.INT_GAIN, "int_gain", 1, 127, 20, "-", _E,
              "integrator gain; larger = more disturbance rejection"),
    ParamSpec(ParamId.TRQ_CONS, "trq_cons", 1, 127, 127, "a=26*v rad/s", _E,
              "first-order torque filter a/(s+a), a = 26 x TrqCons"),
    ParamSpec(ParamId.MAX_SPEED, "max_speed", 1, 127, 48, "(v+3)^2/16*12.21 rpm", _E,
              "S-curve maximum speed code"),
    ParamSpec(ParamId.MAX_ACCEL, "max_accel", 1, 127, 30, "v*635.78 rpm/s", _E,
              "S-curve acceleration code; also speed-mode soft start"),
    ParamSpec(ParamId.ON_RANGE, "on_range", 1, 127, 10, "1/16384 rev", _E,
              "on-position window; 127 turns JP3-9 into the brake output BKO"),
    ParamSpec(ParamId.GEAR_NUM, "gear_num", 500, 16384, 4096, "pulses per 1/4 rev", _E,
              "electronic gear: 4 x GEAR_NUM pulses per revolution"),
    ParamSpec(ParamId.LINE_NUM, "line_num", 500, 4095, 4000, "-", _E,
              "LINE_NUM (DYN CAN parameter group 3); default is a servobus choice"),
    ParamSpec(ParamId.TORQUE_LIMIT, "torque_limit", 1, 127, 127, "127 = no limit", _E,
              "torque limit (DYN5); 127 = no limit"),
)

BY_ID: dict[ParamId, ParamSpec] = {p.id: p for p in PARAMS}
BY_NAME: dict[str, ParamSpec] = {p.name: p for p in PARAMS}

#: The eight DYN parameters in the order DMMDRV and the CLI show them.
DYN_PARAMS: tuple[str, ...] = (
    "main_gain", "speed_gain", "int_gain", "trq_cons",
    "max_speed", "max_accel", "on_range", "gear_num",
)


def spec(name_or_id: str | ParamId) -> ParamSpec:
    """Look a parameter up by snake_case name or ParamId; unknown names raise ArgumentRangeError."""
    if isinstance(name_or_id, ParamId):
        return BY_ID[name_or_id]
    try:
        return BY_NAME[name_or_id]
    except KeyError:
        raise ArgumentRangeError(
            f"unknown parameter {name_or_id!r}; known: {', '.join(BY_NAME)}"
        ) from None


def defaults() -> dict[str, int]:
    return {p.name: p.default for p in PARAMS}
