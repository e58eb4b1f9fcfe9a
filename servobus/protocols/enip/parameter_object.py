"""The DYN5 Parameter object (class 0x0F) on the shared drive core. No I/O.

Reads and writes of attribute 1 follow ``servobus.families.dyn5.params`` (the one instance table)
and the general rules of manual 4.1:

* reads of write-only or non-existent instances (1..255) return 0x12345;
* a write must carry exactly 4 data bytes, else error 05 (checked first, for every
  instance: the length is a property of the request, not of the instance);
* writes to read-only or non-existent instances do nothing and succeed (0x14 answers 05);
* out-of-range writes answer 05; accepted writes go to RAM only.

Decisions: a range-valid command the drive cannot carry out now (servo free, alarm, torque
mode for a position command) is still a successful write: the DYN5 reports execution in
the status word, not in the reply. The drive core takes the DYN5's own ranges (its family
table: GEAR_NUM 1..16384, LINE_NUM 1..4095), not the DYN2's. The torque-mode speed limit
(0x27) goes to the core's torque servo, whose speed loop clamps the torque at the limit
(VirtualDrive.set_torque_speed_limit); like every value here it is lost at Reset.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from servobus.families.dmm.registers import ServoMode
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.family import DYN5
from servobus.families.dyn5.params import Instance, Kind
from servobus.sim.dmm.drive import VirtualDrive

_SPEED_LIMIT = dyn5.BY_NAME["torque_speed_limit"].number


class Effect(Enum):
    NONE = "none"
    RESET = "reset"  # 0x21 = 0xABCD: the adapter resets after answering
    COMMAND = "command"  # a drive command was issued (cancels a fieldbus-loss stop)


@dataclass(frozen=True)
class WriteResult:
    ok: bool
    effect: Effect = Effect.NONE


_REFUSED = WriteResult(False)
_DONE = WriteResult(True)
_COMMANDED = WriteResult(True, Effect.COMMAND)


class ParameterObject:
    """Attribute 1 of every Parameter instance, mapped onto one VirtualDrive."""

    def __init__(self, drive: VirtualDrive) -> None:
        self.drive = drive
        drive.set_family(DYN5)  # the DYN5's parameter ranges, not the DYN2's
        self.power_on()

    def power_on(self) -> None:
        """RAM values of the EtherNet/IP module after power-up or Reset."""
        self._stored = {i.number: i.default for i in dyn5.INSTANCES if i.kind is Kind.STORED}
        self._torque_command = 0
        self._diagnostic = 0
        self.drive.set_torque_speed_limit(self._stored[_SPEED_LIMIT])

    # ---------------------------------------------------------------- reads
    def read(self, number: int) -> int:
        """The UDINT value (signed values as Python negatives) a read returns."""
        inst = dyn5.BY_NUMBER.get(number)
        if inst is None or not inst.readable:
            return dyn5.UNREADABLE
        if inst.kind is Kind.STORED:
            return self._stored[number]
        if inst.kind is Kind.PARAMETER:
            assert inst.param is not None
            return self.drive.get_param(inst.param)
        if inst.kind is Kind.READOUT:
            return self._readout(inst)
        return self._command_state(inst)

    def _readout(self, inst: Instance) -> int:
        d = self.drive
        name = inst.name
        if name == "drive_status":
            return status_word(d)
        if name == "motor_speed":
            return round(d.speed_rpm)
        if name == "motor_position":
            return dyn5.wrap_position(d.position)
        if name == "motor_torque":
            return torque_readout(d)
        if name == "diagnostic_counter":
            self._diagnostic = (self._diagnostic + 1) % dyn5.DIAGNOSTIC_COUNTER_MODULO
            return self._diagnostic
        return inst.default  # constants (EIP firmware)

    def _command_state(self, inst: Instance) -> int:
        if inst.name == "sw_enable":
            return dyn5.DISABLE if self.drive.read_config().free else dyn5.ENABLE
        if inst.name == "command_mode":
            return dyn5.TORQUE_MODE if self.torque_mode else dyn5.POSITION_SPEED_MODE
        if inst.name == "torque_command":
            return self._torque_command
        return 0  # set_abs_origin: a write resets the drive, which clears it

    @property
    def torque_mode(self) -> bool:
        return self.drive.read_config().servo_mode is ServoMode.TORQUE

    def read_bytes(self, number: int) -> bytes:
        return dyn5.encode_udint(self.read(number))

    # ---------------------------------------------------------------- writes
    def write(self, number: int, data: bytes) -> WriteResult:
        if len(data) != dyn5.WRITE_SIZE:
            return _REFUSED
        inst = dyn5.BY_NUMBER.get(number)
        if inst is None:
            return _DONE  # non-existent: no effect, no error
        if not inst.writable:
            return _REFUSED if inst.write_error else _DONE
        value = inst.decode(data)
        if not inst.valid(value):
            return _REFUSED
        if inst.kind is Kind.STORED:
            self._stored[number] = value
            if number == _SPEED_LIMIT:
                self.drive.set_torque_speed_limit(value)
            return _DONE
        if inst.kind is Kind.PARAMETER:
            assert inst.param is not None
            return _DONE if self.drive.set_param(inst.param, value, ram_only=True) else _REFUSED
        return self._command(inst, value)

    def _command(self, inst: Instance, value: int) -> WriteResult:
        d = self.drive
        name = inst.name
        if name == "drive_reset":
            return WriteResult(True, Effect.RESET)
        if name == "set_abs_origin":
            d.set_origin()
            self.reset_drive()
        elif name == "sw_enable":
            if value == dyn5.ENABLE:
                d.enable()
            else:
                d.disable()
        elif name == "command_mode":
            d.set_torque_mode(value == dyn5.TORQUE_MODE)
            self._torque_command = 0
        elif name == "torque_command":
            self._torque_command = value
            d.torque_command(dyn5.torque_to_amps(value, d.model.peak_current_a))
        else:
            _MOTION[name](d, value)
        return _COMMANDED

    def reset_drive(self) -> None:
        """The drive side of a Reset: power cycle, RAM values lost, software enable on."""
        self.drive.reset()
        self.drive.enable()
        self.power_on()


_MOTION = {
    "turn_const_speed": VirtualDrive.turn_const_speed,
    "square_wave_amplitude": VirtualDrive.square_wave,
    "sine_wave_amplitude": VirtualDrive.sine_wave,
    "ss_frequency": VirtualDrive.set_wave_frequency,
    "go_absolute_pos": VirtualDrive.move_absolute,
    "go_relative_pos": VirtualDrive.move_relative,
}


def status_word(drive: VirtualDrive) -> int:
    """Instance 0x02 / input image word 3: the defined bits b0..b5 of the status byte."""
    return drive.read_status().to_byte() & dyn5.STATUS_MASK


def torque_readout(drive: VirtualDrive) -> int:
    """Instance 0x1F / input image word 2: 2000 = peak current, positive = CCW."""
    return dyn5.amps_to_torque(-drive.current_a, drive.model.peak_current_a)
