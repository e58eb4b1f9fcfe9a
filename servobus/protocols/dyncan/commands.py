"""Pure DYN CAN commands: ``make_*`` build a CanCommand; the client sends it and parses the reply.

No I/O. Every argument is range-checked against the one table (codec SPECS and
drive.params) before a frame exists, so out-of-range data never reaches the bus and the
drive's Drive Error 0xFF only ever answers a foreign or corrupted request.

Drive ids: 1..63 address one drive; 0 is the broadcast id. Commands without a reply may
be broadcast (:func:`broadcast`); a read sent to id 0 is answered by every drive on its
own identifier, which on a one-drive bus is how a host finds that drive (the client then
accepts the first answer).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Generic, TypeVar

from servobus import checks
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import params as P
from servobus.families.dmm.registers import DriveConfig, DriveStatus
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.families.dmm.vocabulary import GeneralReadSelector as GR
from servobus.protocols.dyncan import codec as c

F = c.Function
Kind = c.Kind
T = TypeVar("T")


def _frame_value(frame: c.Frame) -> int:
    return frame.value


def _no_reply(frame: c.Frame) -> None:
    """``parse`` of a command without a reply (never called: nothing comes back)."""


@dataclass(frozen=True)
class CanCommand(Generic[T]):
    """One request frame plus how to read its reply: ``parse`` maps the reply frame to the
    result of executing the command (``CanCommand[None]``: no reply)."""

    frame: c.Frame
    kind: Kind
    parse: Callable[[c.Frame], T] = field(kw_only=True)
    guard_item: str | None = None  # EEPROM item for the write guard (settings only)

    @property
    def drive_id(self) -> int:
        return self.frame.drive_id

    @property
    def function(self) -> c.Code:
        return c.function_of(self.frame.function)

    @property
    def expects_reply(self) -> bool:
        return c.expects_reply(self.frame)

    @property
    def retry_safe(self) -> bool:
        """Only reads are ever re-sent; motion and settings never are."""
        return self.kind is Kind.READ


def check_drive_id(drive_id: int, *, allow_broadcast: bool = True) -> int:
    lo = c.BROADCAST_ID if allow_broadcast else c.MIN_DRIVE_ID
    if isinstance(drive_id, bool) or not isinstance(drive_id, int):
        raise ArgumentRangeError(f"drive id must be an integer, got {drive_id!r}")
    if not lo <= drive_id <= c.MAX_DRIVE_ID:
        raise ArgumentRangeError(
            f"DYN CAN drive id {drive_id} is outside {lo}..{c.MAX_DRIVE_ID} (0 = broadcast)"
        )
    return drive_id


def check_value(function: c.Code, value: int, what: str) -> int:
    spec = c.SPECS[function]
    if isinstance(value, bool) or not isinstance(value, int):
        raise ArgumentRangeError(f"{what} must be an integer, got {value!r}")
    if not spec.accepts(value):
        allowed = (", ".join(f"0x{v:02x}" for v in spec.codes) if spec.codes
                   else f"{spec.minimum}..{spec.maximum}")
        raise ArgumentRangeError(f"{what}={value} is outside the allowed range {allowed}")
    return value


class _NoData:
    """Marks a request without a value (reads); a caller's ``None`` is a value and fails."""


_NO_DATA = _NoData()


def _cmd(drive_id: int, function: c.Code, value: int | _NoData = _NO_DATA, *, what: str = "value",
         parse: Callable[[c.Frame], T], guard_item: str | None = None,
         raw: bytes | None = None) -> CanCommand[T]:
    """Every value a caller gives is checked, ``None`` included (it would encode as 0 and
    move the motor to 0); only builders of requests without data omit ``value``."""
    spec = c.SPECS[function]
    if spec.kind is Kind.INTERNAL:
        raise ArgumentRangeError(f"{function.name} is internal to DMM; never sent")
    check_drive_id(drive_id)
    data: int | None = None
    if not isinstance(value, _NoData):
        data = check_value(function, value, what)
    return CanCommand(c.request(drive_id, function, data, raw=raw), spec.kind, parse=parse,
                      guard_item=guard_item)


def _send(drive_id: int, function: c.Code, value: int | _NoData = _NO_DATA, *, what: str = "value",
          guard_item: str | None = None) -> CanCommand[None]:
    """A command without a reply (motion, settings, actions)."""
    return _cmd(drive_id, function, value, what=what, parse=_no_reply, guard_item=guard_item)


# ------------------------------------------------------------------ motion
def make_move_absolute(drive_id: int, position: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.GO_ABSOLUTE_POS, position, what="position")


def make_move_relative(drive_id: int, distance: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.GO_RELATIVE_POS, distance, what="distance")


def make_linear_line_word(drive_id: int, value: int) -> CanCommand[None]:
    """One Make_LinearLine word (the CAN manual gives no word order; see DYN232M 7.5)."""
    return _send(drive_id, DmmFunction.MAKE_LINEAR_LINE, value, what="line word")


def make_circular_arc_word(drive_id: int, value: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.MAKE_CIRCULAR_ARC, value, what="arc word")


def make_turn_const_speed(drive_id: int, rpm: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.TURN_CONST_SPEED, rpm, what="rpm")


def make_square_wave(drive_id: int, amplitude: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.SQUARE_WAVE, amplitude, what="amplitude")


def make_sine_wave(drive_id: int, amplitude: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.SIN_WAVE, amplitude, what="amplitude")


def make_wave_frequency(drive_id: int, hz: int) -> CanCommand[None]:
    return _send(drive_id, DmmFunction.SS_FREQUENCY, hz, what="frequency")


def make_sync_load(drive_id: int, value: int, *, relative: bool = False) -> CanCommand[None]:
    """Load a synchronized move (motion starts at the Sync_Trigger)."""
    fn = F.GO_RELATIVE_POS_SYNC if relative else F.GO_ABSOLUTE_POS_SYNC
    return _send(check_drive_id(drive_id, allow_broadcast=False), fn, value,
                what="distance" if relative else "position")


def make_sync_trigger(*, relative: bool = False,
                      drive_id: int = c.BROADCAST_ID) -> CanCommand[None]:
    code = c.SyncTrigger.RELATIVE if relative else c.SyncTrigger.ABSOLUTE
    return _send(drive_id, F.SYNC_TRIGGER, int(code))


def make_position_direct(drive_id: int, step: int) -> CanCommand[None]:
    """Position Direct relative step, -16384..16384, no profile (0x1C)."""
    return _send(drive_id, F.POSITION_DIRECT, step, what="position direct step")


def make_set_origin(drive_id: int) -> CanCommand[None]:
    """Sent as one byte 0xFF (section 6); the node also accepts no data."""
    return _send(drive_id, DmmFunction.SET_ORIGIN, c.ORIGIN_CODE)


# ------------------------------------------------------------------ actions
def make_servo(drive_id: int, enable: bool) -> CanCommand[None]:
    code = c.ServoCommand.ENABLE if enable else c.ServoCommand.DISABLE
    return _send(drive_id, F.SERVO_DISABLE, int(code))


def make_enable(drive_id: int) -> CanCommand[None]:
    return make_servo(drive_id, True)


def make_disable(drive_id: int) -> CanCommand[None]:
    return make_servo(drive_id, False)


def make_reset(drive_id: int) -> CanCommand[None]:
    """General_Read 0x1C: drive reset, as on DYN232M (same firmware; not in the CAN manual)."""
    return CanCommand(c.request(check_drive_id(drive_id), DmmFunction.GENERAL_READ, int(GR.RESET)),
                      Kind.ACTION, parse=_no_reply)


# ------------------------------------------------------------------ settings (EEPROM)
def make_set_config(drive_id: int, config: DriveConfig | int) -> CanCommand[None]:
    value = config.to_byte() if isinstance(config, DriveConfig) else config
    return _send(drive_id, DmmFunction.SET_DRIVE_CONFIG, value, what="config", guard_item="config")


def make_assign_id(drive_id: int, new_id: int) -> CanCommand[None]:
    """New ids are 1..63 (the drive accepts 0..64, but 0 is broadcast and 64 has no id bits)."""
    check_drive_id(new_id, allow_broadcast=False)
    return _send(check_drive_id(drive_id), DmmFunction.ASSIGN_DRIVE_ID, new_id, what="new id",
                guard_item="drive_id")


def group_of(name: str) -> tuple[c.Code, c.Code, int]:
    """(set function, read function, field index) of a parameter reachable over CAN."""
    spec = P.spec(checks.param_name(name))
    try:
        return c.PARAM_GROUPS[spec.name]
    except KeyError:
        raise ArgumentRangeError(
            f"parameter {name!r} is not reachable over DYN CAN; "
            f"available: {', '.join(c.PARAM_GROUPS)}"
        ) from None


def make_set_params(drive_id: int, values: Mapping[str, int]) -> list[CanCommand[None]]:
    """One group write per group touched; the other fields of a group are sent as 0
    (= leave unchanged). Every value is checked before any frame is built."""
    groups: dict[c.Code, list[int]] = {}
    names: dict[c.Code, list[str]] = {}
    if not isinstance(values, Mapping):
        raise ArgumentRangeError(f"parameter values must be a mapping, got {values!r}")
    for name, value in values.items():
        set_fn, _, index = group_of(name)
        P.spec(name).check(value)
        fields = groups.setdefault(set_fn, [0] * len(c.SPECS[set_fn].fields))
        fields[index] = value
        names.setdefault(set_fn, []).append(P.spec(name).name)
    check_drive_id(drive_id)
    return [CanCommand(c.request(drive_id, fn, fields=tuple(vals)), Kind.SETTING,
                       parse=_no_reply, guard_item=",".join(names[fn]))
            for fn, vals in groups.items()]


def make_set_param(drive_id: int, name: str, value: int) -> CanCommand[None]:
    (command,) = make_set_params(drive_id, {checks.param_name(name): value})
    return command


# ------------------------------------------------------------------ reads
def make_read_group(drive_id: int, function: c.Code) -> CanCommand[dict[str, int]]:
    if not isinstance(function, DmmFunction | F):
        raise ArgumentRangeError(f"{function!r} is not a DYN CAN function")
    spec = c.SPECS[function]
    if not (spec.kind is Kind.READ and spec.fields):
        raise ArgumentRangeError(f"{function.name} is not a parameter group read")
    names = tuple(f.param for f in spec.fields)

    def parse(frame: c.Frame) -> dict[str, int]:
        return dict(zip(names, frame.fields(), strict=True))

    return _cmd(drive_id, function, parse=parse)


def make_read_param(drive_id: int, name: str) -> CanCommand[int]:
    _, read_fn, index = group_of(name)
    group = make_read_group(drive_id, read_fn)

    def parse(frame: c.Frame) -> int:
        return frame.fields()[index]

    return CanCommand(group.frame, group.kind, parse=parse)


def _unsigned(frame: c.Frame) -> int:
    return frame.unsigned


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_status(drive_id: int) -> CanCommand[DriveStatus]:
    return _cmd(drive_id, DmmFunction.READ_DRIVE_STATUS,
                parse=lambda f: DriveStatus.from_byte(f.unsigned))


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_config(drive_id: int) -> CanCommand[DriveConfig]:
    return _cmd(drive_id, DmmFunction.READ_DRIVE_CONFIG,
                parse=lambda f: DriveConfig.from_byte(f.unsigned))


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_id(drive_id: int) -> CanCommand[int]:
    return _cmd(drive_id, DmmFunction.READ_DRIVE_ID, parse=_unsigned)


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_position(drive_id: int) -> CanCommand[int]:
    """General_Read 0x1B: absolute position, encoder counts (reply on 0x0E)."""
    return _cmd(drive_id, DmmFunction.GENERAL_READ, int(GR.POSITION), parse=_frame_value)


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_torque(drive_id: int) -> CanCommand[int]:
    """General_Read 0x1E: torque, 700 = peak current, positive = CCW."""
    return _cmd(drive_id, DmmFunction.GENERAL_READ, int(GR.TORQUE), parse=_frame_value)


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_speed(drive_id: int) -> CanCommand[int]:
    """Read_Motor_Speed (0x1A): rpm, 2 bytes."""
    return _cmd(drive_id, F.READ_MOTOR_SPEED, parse=_frame_value)


@functools.cache  # immutable result: built once per drive id (hot polling path)
def make_read_counter(drive_id: int) -> CanCommand[int]:
    return _cmd(drive_id, F.DIAGNOSTIC_COUNTER, parse=_unsigned)


ECHO_LENGTH = 4  # section 6: Echo carries four data bytes and returns them


def _frame_data(frame: c.Frame) -> bytes:
    return frame.data


def make_echo(drive_id: int, data: bytes) -> CanCommand[bytes]:
    payload = checks.data_bytes("echo", data, ECHO_LENGTH)
    return _cmd(drive_id, F.ECHO, raw=payload, parse=_frame_data)


def broadcast(command: CanCommand[T]) -> CanCommand[T]:
    """Re-target a no-reply command to every drive (id 0)."""
    if command.expects_reply:
        raise ArgumentRangeError(f"{command.function.name} expects a reply: address one drive")
    return replace(command, frame=replace(command.frame, drive_id=c.BROADCAST_ID))


#: The family parameters DYN CAN reaches (fields of parameter groups 1-3, section 6).
REACHABLE_PARAMS: tuple[str, ...] = tuple(c.PARAM_GROUPS)
