"""DYN CAN front end: virtual nodes on one CAN bus (DYN CAN specification section 6).

Pure-ish like :mod:`servobus.protocols.dyn232.device`: ``DynCanNetwork.handle(frame)`` executes one
host frame on every node it addresses and returns the frames the nodes send back; the
caller advances the drives' time first. :func:`serve` runs a network on any FramePort
(a python-can bus, the socketcand hub) in wall-clock time.

Decisions where the manual is silent (kept here, in one place):

* **Addressing.** A node executes frames whose identifier holds its id or the broadcast id
  0. A reply reuses the request's identifier; a read sent to the broadcast id is answered
  by every node on its *own* identifier (CAN arbitration serialises them; this is how a
  host finds the id of an unknown drive).
* **Drive Error 0xFF** answers exactly the ranges the manual lists: positions and sync
  positions -134,217,728..134,217,727, speed +-20,000, wave amplitude 0..4,096, frequency
  0..50, parameters 1..127 (0 = unchanged), GEAR_NUM 500..16,384, LINE_NUM 500..4,095,
  Assign id 0..64. An invalid group write changes nothing (all or nothing).
* **Ignored without an answer:** a data length outside the table (counted in
  ``malformed``), Position Direct outside +-16,384 (no Drive Error listed), unknown
  Sync_Trigger / Servo_Disable / General_Read codes, ForMotorDefine and TBD, and Assign
  id 0 or 64 (inside the checked range, but not an addressable node id: 0 is broadcast,
  64 does not fit the six identifier bits).
* **Sync moves.** Go_*_Sync loads one pending target per kind; Sync_Trigger 0xFF / 0xEE
  starts it and consumes it (a second trigger without a new load does nothing, so a
  repeated trigger never moves twice). Loading does not move the motor.
* **Set_Origin** with 0 data bytes or 1 byte 0xFF (docs/dyncan.md); another byte is ignored.
* **Set_Drive_Config:** bits 7 and 6 are unimplemented and masked off.
* **General_Read** answers 0x1B position (counts, low 32 bits, 1..4 bytes), 0x1E torque
  (700 = peak current) and 0x1D speed (rpm) on 0x0E; 0x1C resets, 0x20 / 0x21 enable /
  disable (the DYN232M selectors: same firmware).
* **Alarm push:** when a drive alarms the node queues Drive Error 0xEE on its own
  identifier (``DynCanNetwork.outbox``); servers send it at once.
* **During an alarm** (6.1: "All commands ... will be ignored") every command is ignored
  by the drive core (``VirtualDrive.accepts_commands``: motion, sync loads, parameter,
  config and id writes, Set_Origin, servo on/off, waves) and nothing is answered: the
  manual's Drive Error codes are 0xFF "data not within range" and 0xEE "alarmed", and 0xEE
  was pushed when the alarm tripped. A frame whose data is outside its range is still
  answered 0xFF: that check is on the frame, before the drive acts on it. Reads are
  answered (6.1: the logic stays powered "for drive diagnostic and drive status reading").
  The same holds while an absolute-mode drive returns to its zero after power-on (section
  6, Set_Origin: "then starts accepting command").
* **Powered off** (``VirtualDrive.power_cycle``, ``supply_dip``): the node answers nothing.
* **Diagnostic counter:** unsigned 8 bits, starts at 0 at power-on, the value sent is the
  count before the increment (+1 per read, 255 wraps to 0).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.dmm import units as U
from servobus.families.dmm.registers import CONFIG_DEFINED_MASK, AlarmCode
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.families.dmm.vocabulary import GeneralReadSelector as GR
from servobus.protocols.dyncan import codec as c
from servobus.sim.dmm.actions import run_action
from servobus.sim.dmm.drive import VirtualDrive

F = c.Function
_INVALID = c.DriveErrorCode.INVALID_DATA
_WRAP32 = 1 << 32


def wrap32(value: int) -> int:
    """Low 32 bits as two's complement (the longest General_Read reply)."""
    return ((value + (1 << 31)) % _WRAP32) - (1 << 31)


def clamp16(value: int) -> int:
    return max(-(1 << 15), min((1 << 15) - 1, value))


class _Invalid(Exception):
    """Raised by a handler: answer Drive Error 0xFF."""


@dataclass
class NodeStats:
    frames: int = 0
    replies: int = 0
    drive_errors: int = 0
    malformed: int = 0
    alarms_pushed: int = 0


class DynCanNode:
    """One VirtualDrive's DYN CAN state (sync targets, diagnostic counter)."""

    def __init__(self, drive: VirtualDrive, push: Callable[[c.Frame], None]) -> None:
        self.drive = drive
        self.sync_absolute: int | None = None
        self.sync_relative: int | None = None
        self.counter = 0
        self.motion_started_at: float | None = None  # drive time of the last accepted motion
        self._push = push
        drive.alarm_listeners.append(self._on_alarm)

    @property
    def drive_id(self) -> int:
        return self.drive.drive_id

    def _on_alarm(self, drive: VirtualDrive, code: AlarmCode) -> None:
        if 1 <= drive.drive_id <= c.MAX_DRIVE_ID:
            self._push(c.drive_error(drive.drive_id, c.DriveErrorCode.ALARM))

    def started(self, accepted: bool) -> None:
        if accepted:
            self.motion_started_at = self.drive.time

    def next_counter(self) -> int:
        value = self.counter
        self.counter = (self.counter + 1) & 0xFF
        return value


Handler = Callable[[DynCanNode, c.Frame], "c.Frame | None"]


class DynCanNetwork:
    """Several VirtualDrives as DYN CAN nodes on one bus."""

    def __init__(self, drives: Sequence[VirtualDrive]) -> None:
        self.outbox: list[c.Frame] = []  # unsolicited frames (alarm push), oldest first
        self.nodes = [DynCanNode(d, self.outbox.append) for d in drives]
        self.stats = NodeStats()
        self._handlers = _build_handlers()

    @property
    def drives(self) -> list[VirtualDrive]:
        return [n.drive for n in self.nodes]

    def node(self, drive_id: int) -> DynCanNode:
        for n in self.nodes:
            if n.drive_id == drive_id:
                return n
        raise KeyError(drive_id)

    def addressed(self, drive_id: int) -> list[DynCanNode]:
        if drive_id == c.BROADCAST_ID:
            return [n for n in self.nodes if n.drive.powered]
        return [n for n in self.nodes if n.drive_id == drive_id and n.drive.powered]

    def handle_raw(self, arbitration_id: int, data: bytes) -> list[c.Frame]:
        try:
            frame = c.decode(arbitration_id, data)
        except FramingError:
            self.stats.malformed += 1
            return []
        return self.handle(frame)

    def handle(self, frame: c.Frame) -> list[c.Frame]:
        """Execute one host frame on every node it addresses; return the replies."""
        self.stats.frames += 1
        spec = c.SPECS[c.function_of(frame.function)]
        handler = self._handlers.get(c.function_of(frame.function))
        if handler is None:
            return []
        if not spec.accepts_length(len(frame.data)):
            self.stats.malformed += 1
            return []
        out: list[c.Frame] = []
        for node in self.addressed(frame.drive_id):
            try:
                reply = handler(node, frame)
            except _Invalid:
                self.stats.drive_errors += 1
                out.append(c.drive_error(node.drive_id, _INVALID))
                continue
            if reply is not None:
                out.append(reply)
        self.stats.replies += len(out)
        return out

    def take_outbox(self) -> list[c.Frame]:
        frames, self.outbox[:] = list(self.outbox), []
        self.stats.alarms_pushed += len(frames)
        return frames


# ---------------------------------------------------------------------- function table
def _checked(frame: c.Frame) -> int:
    """The signed value of a SIGNED request; Drive Error when the table says so."""
    spec = frame.spec
    value = frame.value
    if not spec.accepts(value):
        if spec.drive_error:
            raise _Invalid
        return _IGNORE
    return value


_IGNORE = 1 << 40  # sentinel value: outside every range, means "ignore silently"


def _motion(method: Callable[[VirtualDrive, int], bool]) -> Handler:
    def run(node: DynCanNode, frame: c.Frame) -> None:
        value = _checked(frame)
        if value != _IGNORE:
            node.started(method(node.drive, value))  # False: drive ignored it (alarm, free)

    return run


def _byte(frame: c.Frame) -> int | None:
    return frame.data[0] if frame.data else None


def _set_origin(node: DynCanNode, frame: c.Frame) -> None:
    if _byte(frame) in (None, c.ORIGIN_CODE):
        node.drive.set_origin()


def _assign_id(node: DynCanNode, frame: c.Frame) -> None:
    new_id = frame.unsigned
    if not frame.spec.accepts(new_id):
        raise _Invalid
    if c.MIN_DRIVE_ID <= new_id <= c.MAX_DRIVE_ID:
        node.drive.assign_id(new_id)


def _load_sync(absolute: bool) -> Handler:
    def load(node: DynCanNode, frame: c.Frame) -> None:
        value = _checked(frame)
        if not node.drive.accepts_commands:  # 6.1: ignored during an alarm, not loaded
            return
        if absolute:
            node.sync_absolute = value
        else:
            node.sync_relative = value

    return load


def _sync_trigger(node: DynCanNode, frame: c.Frame) -> None:
    code = _byte(frame)
    if code == c.SyncTrigger.ABSOLUTE and node.sync_absolute is not None:
        target, node.sync_absolute = node.sync_absolute, None
        node.started(node.drive.move_absolute(target))
    elif code == c.SyncTrigger.RELATIVE and node.sync_relative is not None:
        distance, node.sync_relative = node.sync_relative, None
        node.started(node.drive.move_relative(distance))


def _servo(node: DynCanNode, frame: c.Frame) -> None:
    code = _byte(frame)
    if code == c.ServoCommand.ENABLE:
        node.drive.enable()
    elif code == c.ServoCommand.DISABLE:
        node.drive.disable()


def _position_direct(node: DynCanNode, frame: c.Frame) -> None:
    value = _checked(frame)
    if value == _IGNORE:
        return
    node.started(node.drive.move_direct(value))


def _general_read(node: DynCanNode, frame: c.Frame) -> c.Frame | None:
    value = _general_read_value(node.drive, frame.data[0])
    return None if value is None else c.reply(_reply_id(node, frame), DF.GENERAL_READ, value)


def _general_read_value(drive: VirtualDrive, code: int) -> int | None:
    try:
        selector = GR(code)
    except ValueError:
        return None
    if selector is GR.POSITION:
        value = wrap32(drive.position)
    elif selector is GR.TORQUE:
        value = torque_can(drive)
    elif selector is GR.SPEED:
        value = wrap32(round(drive.speed_rpm))
    else:
        run_action(drive, selector)
        return None
    return value


def torque_can(drive: VirtualDrive) -> int:
    """Torque on the CAN scale: 700 = peak current; positive = CCW (section 6: the example's
    negative reading is "applied in CW direction"), while ``current_a`` is positive CW."""
    full = U.CAN_TORQUE_FULL_SCALE
    return max(-full, min(full, round(-drive.current_a / drive.model.peak_current_a * full)))


def _set_group(node: DynCanNode, frame: c.Frame) -> None:
    spec = frame.spec
    values = frame.fields()
    if not all(c.field_valid(f, v) for f, v in zip(spec.fields, values, strict=True)):
        raise _Invalid
    drive = node.drive
    if frame.function == F.SET_PARAM_GROUP2:  # EEPROM only for the first 10 per power-on
        drive.set_speed_accel_group(values[0], values[1])
        return
    for f, v in zip(spec.fields, values, strict=True):
        if v:
            drive.set_param(f.param, v)


def _read_group(node: DynCanNode, frame: c.Frame) -> c.Frame:
    spec = frame.spec
    values = tuple(node.drive.get_param(f.param) for f in spec.fields)
    return c.reply(_reply_id(node, frame), c.function_of(frame.function), fields=values)


def _reply_id(node: DynCanNode, frame: c.Frame) -> int:
    """The request's identifier, or the node's own for broadcast requests."""
    return frame.drive_id if frame.drive_id != c.BROADCAST_ID else node.drive_id


def _reader(read: Callable[[DynCanNode], int]) -> Handler:
    def run(node: DynCanNode, frame: c.Frame) -> c.Frame:
        return c.reply(_reply_id(node, frame), c.function_of(frame.function), read(node))

    return run


def _echo(node: DynCanNode, frame: c.Frame) -> c.Frame:
    return c.reply(_reply_id(node, frame), F.ECHO, raw=frame.data)


def _build_handlers() -> dict[c.Code, Handler]:
    def set_config(node: DynCanNode, frame: c.Frame) -> None:
        node.drive.set_config(frame.unsigned & CONFIG_DEFINED_MASK)  # b7 b6 unimplemented

    table: dict[c.Code, Handler] = {
        DF.SET_ORIGIN: _set_origin,
        DF.GO_ABSOLUTE_POS: _motion(VirtualDrive.move_absolute),
        DF.MAKE_LINEAR_LINE: _motion(VirtualDrive.linear_line_word),
        DF.GO_RELATIVE_POS: _motion(VirtualDrive.move_relative),
        DF.MAKE_CIRCULAR_ARC: _motion(VirtualDrive.circular_arc_word),
        DF.ASSIGN_DRIVE_ID: _assign_id,
        DF.READ_DRIVE_ID: _reader(lambda n: n.drive_id),
        DF.SET_DRIVE_CONFIG: set_config,
        DF.READ_DRIVE_CONFIG: _reader(lambda n: n.drive.read_config().to_byte()),
        DF.READ_DRIVE_STATUS: _reader(lambda n: n.drive.read_status().to_byte()),
        DF.TURN_CONST_SPEED: _motion(VirtualDrive.turn_const_speed),
        DF.SQUARE_WAVE: _motion(VirtualDrive.square_wave),
        DF.SIN_WAVE: _motion(VirtualDrive.sine_wave),
        DF.SS_FREQUENCY: _motion(VirtualDrive.set_wave_frequency),
        DF.GENERAL_READ: _general_read,
        F.GO_ABSOLUTE_POS_SYNC: _load_sync(absolute=True),
        F.GO_RELATIVE_POS_SYNC: _load_sync(absolute=False),
        F.SYNC_TRIGGER: _sync_trigger,
        F.SERVO_DISABLE: _servo,
        F.READ_MOTOR_SPEED: _reader(lambda n: clamp16(round(n.drive.speed_rpm))),
        F.POSITION_DIRECT: _position_direct,
        F.ECHO: _echo,
        F.DIAGNOSTIC_COUNTER: _reader(DynCanNode.next_counter),
        # FOR_MOTOR_DEFINE, TBD: ignored. DRIVE_ERROR: drive -> host only.
    }
    for spec in c.SPECS.values():  # parameter groups come from the codec table
        if spec.fields:
            table[spec.function] = _set_group if spec.kind is c.Kind.SETTING else _read_group
    return table
