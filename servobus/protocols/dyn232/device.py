"""DYN232M protocol front end: one RS485 line of VirtualDrives (DYN2 manual section 7).

Pure-ish: no I/O and no clock. ``Dyn232Line.receive(data)`` takes host bytes in any
chunking and returns the bytes the drives send back; the caller advances the drives' time
first (servers via :mod:`servobus.sim.wall_clock`, tests via ``VirtualDrive.advance``).
Pacing lives in :mod:`servobus.protocols.dyn232.pacing`, sockets in
:mod:`servobus.protocols.dyn232.server`.

Decisions where the manual is silent (kept here, in one place):

* **Addressing.** A drive executes packets whose start byte holds its id or the broadcast
  id 127, and answers with its own id (docs/dyn232.md). Packets for ids nobody has get silence.
* **Several answers to one packet** (a broadcast read with more than one drive on the line,
  or two drives sharing an id): on a real line the replies collide and the host receives
  garbage that fails its checksum. The simulator models that as *silence*: every addressed
  drive still executes the read (so a status read still clears its checksum notice), but no
  reply is sent. A broadcast read with exactly one drive on the line is answered; that is
  how a host finds the id of a single unknown drive.
* **Bad checksum.** The packet is not executed and alarm code 4 is set on the drive(s) that
  its start byte addresses (a drive decides by the first byte alone, manual 7.8; a corrupted
  id byte is therefore attributed to whichever drive it names, as a real line would). The
  next status read reports code 4 and clears it (``VirtualDrive.note_checksum_error``).
  Framing errors (truncated packets, stray bytes) are dropped without any alarm: no packet
  was received, so there was nothing to check.
* **Parameter and register writes** (Set_MainGain .. Set_GearNumber, Set_Drive_Config,
  Assign_Drive_ID): a 1-byte value is read as 7-bit unsigned (the ranges are 1..127 and the
  manual lists these as one byte, as DMM's library sends them); longer values are signed.
  Out-of-range writes are ignored silently: ``VirtualDrive.set_param`` rejects them against
  the one parameter table, nothing is stored, nothing is sent (these functions never reply).
  Assign_Drive_ID accepts 0..63 only (64..126 are reserved, 127 is broadcast).
* **Readouts that do not fit the packet.** The position readout is the low 28 bits of the
  drive's position counter, as two's complement (the wire carries 28-bit signed data).
* **During an alarm** (6.1: "All commands including pulse, analog and RS232 will be
  ignored") the drive core ignores every command (``VirtualDrive.accepts_commands``):
  motion, parameter, config and id writes, Set_Origin, servo on/off; none of them replies
  on DYN232M anyway, so the wire shows nothing. Reads (status, config, id, parameters,
  General_Read position/speed/torque) are answered, and the 0x1C reset (a power cycle)
  works. The same while an absolute-mode drive returns to its zero after power-on (7.3).
* **Powered off** (``VirtualDrive.power_cycle``, ``supply_dip``): the drive neither
  executes nor answers anything.
* ForMotorDefine (0x0F) is DMM-internal and ignored; unknown General_Read selectors are
  ignored (no reply).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

from servobus.errors import ChecksumError, ProtocolError
from servobus.families.dmm.vocabulary import DmmFunction
from servobus.protocols.dyn232 import codec as c
from servobus.sim.dmm.actions import run_action
from servobus.sim.dmm.drive import VirtualDrive

H = c.HostFunction
GR = c.GeneralReadSelector

_WRAP = 1 << 28


def wrap28(value: int) -> int:
    """Low 28 bits of ``value`` as two's complement (the packet's data range)."""
    return ((value - c.VALUE_MIN) % _WRAP) + c.VALUE_MIN


def host_value(packet: c.Packet) -> int:
    """Value of a host packet: 1-byte register/parameter writes are 7-bit unsigned."""
    try:
        spec = c.HOST_SPECS[c.host_function(packet.function)]
    except ValueError:
        return packet.value
    if spec.kind is c.Kind.SETTING and len(packet.data) == 1:
        return packet.unsigned
    return packet.value


Handler = Callable[[VirtualDrive, int], "int | None"]
#: handler, value, reply function (None: no reply), addressed id (127 = broadcast)
_Plan = tuple[Handler, int, "c.DriveFunction | None", int]
MAX_CACHED = 1024  # bound on cached plans / reply encodings (a run of distinct values)


class Dyn232Line:
    """Several VirtualDrives sharing one DYN232M RS485 line."""

    def __init__(self, drives: Sequence[VirtualDrive]) -> None:
        self.drives: list[VirtualDrive] = list(drives)
        self.framer = c.Framer()
        self.packets = 0  # valid packets seen on the line (any id)
        self.checksum_errors = 0
        self.framing_errors = 0
        self.collisions = 0  # replies suppressed because several drives would answer
        self._handlers: dict[c.HostCode, Handler] = _build_handlers()
        self._plans: dict[bytes, _Plan | None] = {}  # request bytes -> plan (handle_whole)
        self._replies: dict[tuple[int, int, int], bytes] = {}  # memoised reply encodings

    # ------------------------------------------------------------------ byte level
    def receive(self, data: bytes | bytearray) -> bytes:
        """Feed host bytes (any chunking); return what the drives send back."""
        out = bytearray()
        for event in self.framer.iter_feed(data):
            out += self.handle(event)
        return bytes(out)

    def events(
        self, data: bytes | bytearray, framer: c.Framer | None = None
    ) -> Iterator[tuple[int, c.FramerEvent]]:
        """Lazily frame ``data``, yielding (index of the byte that completed it, event).

        The pacing layer uses the index to execute each packet only once its last byte
        could have arrived on the wire. ``framer`` lets several host ports share one line.
        """
        fr = self.framer if framer is None else framer
        for i in range(len(data)):
            for event in fr.iter_feed(data[i : i + 1]):
                yield i, event

    # ------------------------------------------------------------------ packet level
    def handle(self, event: c.FramerEvent) -> bytes:
        """Execute one framer event; return the reply bytes (possibly empty)."""
        if isinstance(event, ChecksumError):
            self.checksum_errors += 1
            if event.raw and not event.raw[0] & 0x80:
                for drive in self.addressed(event.raw[0] & 0x7F):
                    drive.note_checksum_error()
            return b""
        if isinstance(event, ProtocolError):
            self.framing_errors += 1
            return b""
        return self.execute(event)

    def addressed(self, drive_id: int) -> list[VirtualDrive]:
        if drive_id == c.BROADCAST_ID:
            return [d for d in self.drives if d.powered]
        return [d for d in self.drives if d.drive_id == drive_id and d.powered]

    def execute(self, packet: c.Packet) -> bytes:
        """Run a valid host packet on every drive it addresses; return the reply bytes."""
        return self._run(self._plan(packet))

    def handle_whole(self, raw: bytes) -> bytes:
        """Same as ``handle`` of the one event ``raw`` frames to, for ``raw`` that is exactly
        one packet (``Framer.whole_packet``) with the port's framer empty: the usual case.

        Plans are cached by the exact request bytes (a poll repeats the same few packets),
        so a repeated request skips decoding and the table look-ups. Only requests with a
        good checksum are cached: the same bytes always check the same way.
        """
        plan = self._plans.get(raw)
        if plan is None:
            try:
                packet = c.decode(raw)
            except ProtocolError as exc:
                return self.handle(exc)
            plan = self._plan(packet)
            if len(self._plans) >= MAX_CACHED:
                self._plans.clear()
            self._plans[bytes(raw)] = plan
        return self._run(plan)

    def _plan(self, packet: c.Packet) -> _Plan | None:
        """What a valid packet does: (handler, value, reply function, addressed id)."""
        try:
            function = c.host_function(packet.function)
        except ValueError:  # pragma: no cover - every 5-bit code is a HostFunction
            return None
        handler = self._handlers.get(function)
        if handler is None:
            return None
        value = host_value(packet)
        return handler, value, c.reply_function(function, value), packet.drive_id

    def _run(self, plan: _Plan | None) -> bytes:
        self.packets += 1
        if plan is None:
            return b""
        handler, value, reply_fn, target = plan
        reply = b""
        n_replies = 0
        for drive in self.drives:  # every addressed drive executes, answering or not
            if (target != c.BROADCAST_ID and drive.drive_id != target) or not drive.powered:
                continue
            result = handler(drive, value)
            if reply_fn is not None and result is not None:
                n_replies += 1
                reply = self._encode_reply(drive.drive_id, reply_fn, result)
        if n_replies > 1:  # several drives answering at once collide: see module doc
            self.collisions += 1
            return b""
        return reply

    def _encode_reply(self, drive_id: int, function: c.DriveFunction, value: int) -> bytes:
        """``c.encode_reply``, memoised: status, config and parameters rarely change."""
        key = (drive_id, function, value)
        raw = self._replies.get(key)
        if raw is None:
            raw = c.encode_reply(drive_id, function, value)
            if len(self._replies) >= MAX_CACHED:
                self._replies.clear()
            self._replies[key] = raw
        return raw


# ---------------------------------------------------------------------- function table
def _build_handlers() -> dict[c.HostCode, Handler]:
    """HostFunction -> handler(drive, value) -> reply value or None (no reply)."""

    def motion(method: Callable[[VirtualDrive, int], bool]) -> Handler:
        def run(drive: VirtualDrive, value: int) -> None:
            method(drive, value)  # False = ignored by the drive (alarm, free, ...): silent

        return run

    def set_origin(drive: VirtualDrive, value: int) -> None:
        drive.set_origin()

    def assign_id(drive: VirtualDrive, value: int) -> None:
        spec = c.HOST_SPECS[DmmFunction.ASSIGN_DRIVE_ID]
        if spec.minimum <= value <= spec.maximum:
            drive.assign_id(value)

    def set_config(drive: VirtualDrive, value: int) -> None:
        drive.set_config(value)

    def general_read(drive: VirtualDrive, value: int) -> int | None:
        try:
            selector = GR(value)
        except ValueError:
            return None
        if selector is GR.POSITION:
            return wrap28(drive.position)
        if selector is GR.SPEED:
            return wrap28(round(drive.speed_rpm))
        if selector is GR.TORQUE:
            return wrap28(int(drive.torque_current))
        run_action(drive, selector)
        return None

    table: dict[c.HostCode, Handler] = {
        DmmFunction.SET_ORIGIN: set_origin,
        DmmFunction.GO_ABSOLUTE_POS: motion(VirtualDrive.move_absolute),
        DmmFunction.GO_RELATIVE_POS: motion(VirtualDrive.move_relative),
        DmmFunction.MAKE_LINEAR_LINE: motion(VirtualDrive.linear_line_word),
        DmmFunction.MAKE_CIRCULAR_ARC: motion(VirtualDrive.circular_arc_word),
        DmmFunction.TURN_CONST_SPEED: motion(VirtualDrive.turn_const_speed),
        DmmFunction.SQUARE_WAVE: motion(VirtualDrive.square_wave),
        DmmFunction.SIN_WAVE: motion(VirtualDrive.sine_wave),
        DmmFunction.SS_FREQUENCY: motion(VirtualDrive.set_wave_frequency),
        DmmFunction.ASSIGN_DRIVE_ID: assign_id,
        DmmFunction.READ_DRIVE_ID: lambda d, v: d.drive_id,
        DmmFunction.SET_DRIVE_CONFIG: set_config,
        DmmFunction.READ_DRIVE_CONFIG: lambda d, v: d.read_config().to_byte(),
        DmmFunction.READ_DRIVE_STATUS: lambda d, v: d.read_status().to_byte(),
        DmmFunction.GENERAL_READ: general_read,
        # DmmFunction.FOR_MOTOR_DEFINE: DMM-internal, deliberately absent (ignored).
    }
    for spec in c.HOST_SPECS.values():  # parameter set/read pairs come from the codec table
        if spec.param is None:
            continue
        if spec.kind is c.Kind.SETTING:
            table[spec.function] = _param_writer(spec.param)
        elif spec.kind is c.Kind.READ:
            table[spec.function] = _param_reader(spec.param)
    return table


def _param_writer(name: str) -> Handler:
    def write(drive: VirtualDrive, value: int) -> None:
        drive.set_param(name, value)  # out of range: ignored by the drive, nothing sent

    return write


def _param_reader(name: str) -> Handler:
    def read(drive: VirtualDrive, value: int) -> int:
        return drive.get_param(name)

    return read
