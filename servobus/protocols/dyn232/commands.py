"""Pure DYN232M commands: ``make_*`` build a Command; an executor sends it and parses the reply.

No I/O here. Every argument is range-checked against the one table (codec HOST_SPECS and
drive.params) before a byte exists, so bad input never reaches the wire. The broadcast id
127 is only reachable through :func:`broadcast` and the interpolation builders.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Generic, TypeVar

from servobus import checks
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import params as P
from servobus.families.dmm.profile import pack_arc_word as pack_arc_word  # one home: drive.profile
from servobus.families.dmm.profile import unpack_arc_word as unpack_arc_word
from servobus.families.dmm.registers import DriveConfig, DriveStatus
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c

H = c.HostFunction
GR = c.GeneralReadSelector
T = TypeVar("T")


def _identity(v: int) -> int:
    return v


def _no_reply(v: int) -> None:
    """``parse`` of a command without a reply (never called: nothing comes back)."""


@dataclass(frozen=True)
class Command(Generic[T]):
    """One host packet plus what to expect back. ``parse`` maps the reply value to the
    result of executing the command (``Command[None]``: no reply)."""

    drive_id: int
    function: c.HostCode
    value: int = 0
    reply: c.DriveFunction | None = None
    kind: c.Kind = c.Kind.ACTION
    parse: Callable[[int], T] = field(kw_only=True)
    param: str | None = None

    def to_bytes(self) -> bytes:
        return c.encode(self.drive_id, self.function, self.value)

    @property
    def expects_reply(self) -> bool:
        return self.reply is not None

    @property
    def retry_safe(self) -> bool:
        """Only reads are ever re-sent; motion and settings never are."""
        return self.kind is c.Kind.READ


def check_drive_id(drive_id: int) -> int:
    if isinstance(drive_id, bool) or not isinstance(drive_id, int):
        raise ArgumentRangeError(f"drive id must be an integer, got {drive_id!r}")
    if not 0 <= drive_id <= c.MAX_DRIVE_ID:
        raise ArgumentRangeError(
            f"drive id {drive_id} is outside 0..{c.MAX_DRIVE_ID} "
            f"(127 is broadcast: use broadcast(); 64..126 are reserved)"
        )
    return drive_id


def _check_value(function: c.HostCode, value: object, what: str) -> int:
    spec = c.HOST_SPECS[function]
    if isinstance(value, bool) or not isinstance(value, int):
        raise ArgumentRangeError(f"{what} must be an integer, got {value!r}")
    if not spec.minimum <= value <= spec.maximum:
        raise ArgumentRangeError(
            f"{what}={value} is outside the allowed range {spec.minimum}..{spec.maximum}"
        )
    return value


def _cmd(drive_id: int, function: c.HostCode, value: int = 0, *,
         parse: Callable[[int], T], reply: c.DriveFunction | None = None,
         param: str | None = None) -> Command[T]:
    spec = c.HOST_SPECS[function]
    return Command(check_drive_id(drive_id), function, value,
                   reply=spec.reply if reply is None else reply, kind=spec.kind, parse=parse,
                   param=param)


def _send(drive_id: int, function: c.HostCode, value: int = 0, *,
          param: str | None = None) -> Command[None]:
    """A command without a reply (motion, settings)."""
    return _cmd(drive_id, function, value, parse=_no_reply, param=param)


# ------------------------------------------------------------------ motion
def make_move_absolute(drive_id: int, position: int) -> Command[None]:
    checked = _check_value(DF.GO_ABSOLUTE_POS, position, "position")
    return _send(drive_id, DF.GO_ABSOLUTE_POS, checked)


def make_move_relative(drive_id: int, distance: int) -> Command[None]:
    checked = _check_value(DF.GO_RELATIVE_POS, distance, "distance")
    return _send(drive_id, DF.GO_RELATIVE_POS, checked)


def make_turn_const_speed(drive_id: int, rpm: int) -> Command[None]:
    return _send(drive_id, DF.TURN_CONST_SPEED, _check_value(DF.TURN_CONST_SPEED, rpm, "rpm"))


def make_square_wave(drive_id: int, amplitude: int) -> Command[None]:
    return _send(drive_id, DF.SQUARE_WAVE, _check_value(DF.SQUARE_WAVE, amplitude, "amplitude"))


def make_sine_wave(drive_id: int, amplitude: int) -> Command[None]:
    return _send(drive_id, DF.SIN_WAVE, _check_value(DF.SIN_WAVE, amplitude, "amplitude"))


def make_wave_frequency(drive_id: int, hz: int) -> Command[None]:
    return _send(drive_id, DF.SS_FREQUENCY, _check_value(DF.SS_FREQUENCY, hz, "frequency"))


def make_set_origin(drive_id: int) -> Command[None]:
    return _send(drive_id, DF.SET_ORIGIN)


def _check_feedrate(feedrate: int, allow_negative: bool) -> int:
    lo = -127 if allow_negative else 1
    if isinstance(feedrate, bool) or not isinstance(feedrate, int) or not (
        lo <= feedrate <= 127 and feedrate != 0
    ):
        raise ArgumentRangeError(f"feedrate={feedrate!r} is outside {lo}..127 (not 0)")
    return feedrate


def make_linear_line(dx: int, dy: int, dz: int, feedrate: int) -> list[Command[None]]:
    """Example 7: four broadcast packets dX, dY, dZ, feedrate (1..127)."""
    _check_feedrate(feedrate, allow_negative=False)
    words = [_check_value(DF.MAKE_LINEAR_LINE, v, n) for v, n in ((dx, "dx"), (dy, "dy"),
                                                                   (dz, "dz"))]
    return [Command(c.BROADCAST_ID, DF.MAKE_LINEAR_LINE, v, kind=c.Kind.MOTION, parse=_no_reply)
            for v in [*words, feedrate]]


def make_circular_arc(
    start: tuple[int, int], end: tuple[int, int], *, plane: int = 0, feedrate: int = 1
) -> list[Command[None]]:
    """Example 8: start and end relative to the centre, then (plane << 8) + feedrate.

    plane 0 = XY, 1 = YZ, 2 = ZX; positive feedrate CW, negative CCW. Servobus packs a
    negative feedrate as plane*256 + F (two's complement addition), decoded symmetrically.
    """
    if isinstance(plane, bool) or plane not in (0, 1, 2):
        raise ArgumentRangeError(f"plane={plane!r} must be 0 (XY), 1 (YZ) or 2 (ZX)")
    _check_feedrate(feedrate, allow_negative=True)
    points = (_point("start", start), _point("end", end))
    words = [_check_value(DF.MAKE_CIRCULAR_ARC, v, "arc coordinate")
             for point in points for v in point]
    return [Command(c.BROADCAST_ID, DF.MAKE_CIRCULAR_ARC, v, kind=c.Kind.MOTION,
                    parse=_no_reply)
            for v in [*words, pack_arc_word(plane, feedrate)]]


def _point(what: str, point: object) -> tuple[object, ...]:
    if not isinstance(point, tuple | list) or len(point) != 2:
        raise ArgumentRangeError(f"{what} must be an (x, y) pair, got {point!r}")
    return tuple(point)


# ------------------------------------------------------------------ actions (no reply)
def _action(drive_id: int, selector: c.GeneralReadSelector) -> Command[None]:
    return Command(check_drive_id(drive_id), DF.GENERAL_READ, int(selector), kind=c.Kind.ACTION,
                   parse=_no_reply)


def make_reset(drive_id: int) -> Command[None]:
    """Drive reset (counts as a power cycle: clears a latched alarm)."""
    return _action(drive_id, GR.RESET)


def make_enable(drive_id: int) -> Command[None]:
    return _action(drive_id, GR.ENABLE)


def make_disable(drive_id: int) -> Command[None]:
    return _action(drive_id, GR.DISABLE)


# ------------------------------------------------------------------ settings (EEPROM)
def make_set_param(drive_id: int, name: str, value: int) -> Command[None]:
    spec = P.spec(checks.param_name(name))
    set_fn, _ = _param_functions(spec.name)
    return _send(drive_id, set_fn, spec.check(value), param=spec.name)


def make_set_config(drive_id: int, config: DriveConfig | int) -> Command[None]:
    value = config.to_byte() if isinstance(config, DriveConfig) else config
    return _send(drive_id, DF.SET_DRIVE_CONFIG, _check_value(DF.SET_DRIVE_CONFIG, value, "config"))


def make_assign_id(drive_id: int, new_id: int) -> Command[None]:
    return _send(drive_id, DF.ASSIGN_DRIVE_ID, _check_value(DF.ASSIGN_DRIVE_ID, new_id, "new id"))


# ------------------------------------------------------------------ reads
def make_read_param(drive_id: int, name: str) -> Command[int]:
    spec = P.spec(checks.param_name(name))
    _, read_fn = _param_functions(spec.name)
    return _cmd(drive_id, read_fn, parse=_identity, param=spec.name)


def make_read_status(drive_id: int) -> Command[DriveStatus]:
    return _cmd(drive_id, DF.READ_DRIVE_STATUS, parse=DriveStatus.from_byte)


def make_read_config(drive_id: int) -> Command[DriveConfig]:
    return _cmd(drive_id, DF.READ_DRIVE_CONFIG, parse=DriveConfig.from_byte)


def make_read_id(drive_id: int) -> Command[int]:
    return _cmd(drive_id, DF.READ_DRIVE_ID, parse=_identity)


def _general_read(drive_id: int, selector: c.GeneralReadSelector) -> Command[int]:
    return _cmd(drive_id, DF.GENERAL_READ, int(selector), parse=_identity,
                reply=c.GENERAL_READ_REPLIES[selector])


def make_read_position(drive_id: int) -> Command[int]:
    """Absolute position in encoder counts (65,536 per revolution)."""
    return _general_read(drive_id, GR.POSITION)


def make_read_speed(drive_id: int) -> Command[int]:
    """Motor speed in rpm."""
    return _general_read(drive_id, GR.SPEED)


def make_read_torque(drive_id: int) -> Command[int]:
    """Torque current, DYN232M relative unit."""
    return _general_read(drive_id, GR.TORQUE)


def broadcast(command: Command[T]) -> Command[T]:
    """Re-target a no-reply command to every drive (id 127). Reads cannot be broadcast."""
    if command.expects_reply:
        raise ArgumentRangeError(
            f"{command.function.name} expects a reply; replies from several drives would collide"
        )
    return replace(command, drive_id=c.BROADCAST_ID)


def _param_functions(name: str) -> tuple[c.HostCode, c.HostCode]:
    try:
        return c.PARAM_FUNCTIONS[name]
    except KeyError:
        raise ArgumentRangeError(
            f"parameter {name!r} is not reachable over DYN232M; "
            f"available: {', '.join(c.PARAM_FUNCTIONS)}"
        ) from None


#: The family parameters DYN232M reaches (one set/read function pair each, 7.2.4).
REACHABLE_PARAMS: tuple[str, ...] = tuple(c.PARAM_FUNCTIONS)
