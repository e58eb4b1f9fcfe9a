"""Control channel of the virtual drives: JP3 I/O, internal state and faults on demand.

A host program talks to a virtual drive over its protocol (DYN232M, DYN CAN, ...); what a
real machine does *around* the drive - the analog reference, a pulse generator, the ENA
switch, the outputs wired to a PLC, a blocked shaft, a supply dip - is reached here, so a
whole machine's software can be tested against virtual drives. The vocabulary is
protocol-free: it talks to :class:`servobus.sim.dmm.drive.VirtualDrive` (any clocked motor built
on one), addressed by drive id.

From Python, :class:`DriveControl` (``execute(request) -> reply``, or its methods); over TCP,
:mod:`servobus.sim.control_server` (JSON lines); the CLI, ``servobus sim control``. Requests
and replies are JSON objects, one per line; docs/sim-control.md lists every command::

    {"cmd": "analog", "id": 1, "volts": 2.5}   ->  {"ok": true, "cmd": "analog", "id": 1}
    {"cmd": "fault", "id": 1, "fault": "over_current"}
    {"cmd": "state", "id": 1}                  ->  {"ok": true, ..., "following_error": 12.5}
    {"cmd": "nope"}                            ->  {"ok": false, "kind": "unknown_command", ...}

Every command and its arguments, with their ranges and defaults, live in one table
(``COMMANDS``), every fault in another (``FAULTS``). A request's ``seq`` (any JSON scalar) is
echoed in its reply. ``id`` may be left out when the channel serves exactly one drive.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from servobus.families.dmm import units as U
from servobus.families.dmm.registers import AlarmCode, CommandMode
from servobus.sim.core import constants as K
from servobus.sim.core import control as channel
from servobus.sim.core.control import Arg, ChannelControl, ControlError, Reply, apply_load, ok
from servobus.sim.core.io import PulseFormat
from servobus.sim.dmm.drive import VirtualDrive

MAX_COUNT = 1 << 31  # |pulses| per request (a 28-bit position range fits many times over)

#: A command of this table: ``run(ctl, drive, args)`` on one drive, or ``run_channel``.
Command = channel.Command[VirtualDrive]


@dataclass(frozen=True)
class Fault:
    name: str
    args: tuple[Arg, ...]
    inject: Callable[[VirtualDrive, dict[str, Any]], None]
    alarm: AlarmCode | None  # what trips (None: a condition that may lead to one)
    doc: str


# ---------------------------------------------------------------------- readouts
def drive_state(d: VirtualDrive) -> Reply:
    """The drive's internal state (units: counts of 65,536 per rev, rpm, A, V, degC)."""
    status = d.peek_status()
    cfg = d.read_config()
    servo = "free" if d.servo_free else cfg.servo_mode.name.lower()
    err = d.following_error_counts
    return {
        "time_s": round(d.time, 6),
        "powered": d.powered,
        "homing": d.homing,
        "alarm": status.alarm.name.lower(),
        "alarm_code": int(status.alarm),
        "status": status.to_byte(),
        "config": cfg.to_byte(),
        "servo": servo,
        "motion_busy": status.motion_busy,
        "position": d.position,
        "reference": round(d.reference_counts, 3),
        "following_error": round(err, 3),
        "following_error_deg": round(err * 360.0 / U.COUNTS_PER_REV, 4),
        "speed_rpm": round(d.speed_rpm, 3),
        "current_a": round(d.current_a, 4),
        "bus_voltage": round(d.bus_voltage, 3),
        "temperature_c": round(d.temperature_c, 2),
        "heat_fraction": round(d.heat_fraction, 5),
        "inputs": {"analog_v": d.analog_input, "ena": d.enable_input,
                   "pulse_format": _decoded_format(d).value},
        "world": d.world(),
    }


def _level(transistor_on: bool) -> str:
    """JP3 open-collector outputs: transistor ON pulls the pin LOW (2.3)."""
    return "low" if transistor_on else "high"


def drive_outputs(d: VirtualDrive) -> Reply:
    """JP3 outputs (2.3, 4.5, 4.6) by meaning and as pin levels (8 ALM, 9 ONPOS/BKO, 10 ZRI).

    Without power every transistor is off and every pin reads HIGH (4.6: BKO OFF, brake
    engaged)."""
    onpos, bko = d.onpos_output, d.brake_released
    powered = d.powered
    if not powered:
        onpos = None if onpos is None else False
        bko = None if bko is None else False
    pin9 = (bko if bko is not None else not onpos) if powered else False
    return {
        "powered": powered,
        "alarm": d.alarm_output,
        "on_position": onpos,
        "brake_released": bko,
        "zero_index": d.zri_output,
        "zri_count": d.zri_count,
        "pins": {"8": _level(d.alarm_output), "9": _level(pin9), "10": _level(d.zri_output)},
    }


def _decoded_format(d: VirtualDrive) -> PulseFormat:
    """The train format the drive decodes (config b1 b0 = 1 is always CW/CCW)."""
    if d.read_config().command_mode is CommandMode.CW_CCW:
        return PulseFormat.CW_CCW
    return d.pulse_format


# ---------------------------------------------------------------------- commands
def _analog(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    d.set_analog_input(a["volts"])
    return ok()


def _pulses(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    count = a["count"]
    if a["seconds"] is not None and a["rate"] is not None:
        raise ControlError("bad_argument", "give rate or seconds, not both")
    if a["seconds"] is not None:
        seconds = a["seconds"]
        if count and seconds and abs(count) / seconds > K.PULSE_RATE_MAX_HZ:
            raise ControlError("bad_argument",
                               f"{abs(count) / seconds:g} pulses/s exceed the inputs' "
                               f"{K.PULSE_RATE_MAX_HZ:g} (4.1)")
    else:
        seconds = abs(count) / (a["rate"] or K.PULSE_RATE_MAX_HZ)
    fmt = PulseFormat(a["format"]) if a["format"] else _decoded_format(d)
    taken = d.input_pulse_train(fmt, count, seconds)
    return ok(format=fmt.value, seconds=seconds, taken=taken, ignored=taken == 0 and count != 0)


def _ena(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    d.set_enable_input(a["enabled"])
    return ok()


def _bus(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    d.set_bus_voltage(a["volts"])
    return ok(alarm=d.alarm.name.lower())


def _load(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    return apply_load(d, d, a)


def _fault(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    fault = FAULTS[a["fault"]]
    fault.inject(d, a)
    return ok(fault=fault.name, alarm=d.alarm.name.lower(), alarm_code=int(d.alarm))


def _clear(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    """Remove the causes (not the alarm: that takes a power cycle, 6.1)."""
    d.set_encoder_fault(False)
    d.set_blocked(False)
    d.set_disturbance(0.0)
    d.set_bus_voltage(K.RATED_BUS_VOLTAGE)
    return ok(alarm=d.alarm.name.lower(), alarm_code=int(d.alarm))


def _power_cycle(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    d.power_cycle(a["off_s"])
    return ok(powered=d.powered)


def _state(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    return ok(**drive_state(d))


def _outputs(ctl: DriveControl, d: VirtualDrive, a: dict[str, Any]) -> Reply:
    return ok(**drive_outputs(d))


# ---------------------------------------------------------------------- faults
def _over_voltage(d: VirtualDrive, a: dict[str, Any]) -> None:
    if a["seconds"]:
        d.supply_dip(a["volts"], a["seconds"])  # a surge: up, then back
    else:
        d.set_bus_voltage(a["volts"])


def _lost_phase(d: VirtualDrive, a: dict[str, Any]) -> None:
    if a["cause"] == "encoder":
        d.set_encoder_fault(True)
    else:
        d.set_blocked(True)


_VOLTS_SURGE = Arg("volts", float, U.OVER_VOLTAGE_V + 0.1, 200.0, default=90.0,
                   doc="bus voltage of the surge (the alarm trips above 80 V, 2.5)")
_SURGE_S = Arg("seconds", float, 0.0, 3600.0, default=0.01,
               doc="how long (simulated s); 0: until `bus` or `clear` sets it back")

FAULTS: dict[str, Fault] = {f.name: f for f in (
    Fault("over_current", (), lambda d, a: d.trip(AlarmCode.OVER_CURRENT),
          AlarmCode.OVER_CURRENT, "a short or a current backlog: alarm 2 at once"),
    Fault("overheat", (Arg("temperature_c", float, K.OVERHEAT_C, 300.0, default=90.0,
                           doc="power stage temperature (trips at 85 degC)"),),
          lambda d, a: d.overheat(a["temperature_c"]), AlarmCode.OVERHEAT,
          "the power stage too hot: alarm 3 at once; it cools with the I2t time constant"),
    Fault("over_voltage", (_VOLTS_SURGE, _SURGE_S), _over_voltage, AlarmCode.OVER_VOLTAGE,
          "a bus surge (regeneration): alarm 5 at once"),
    Fault("lost_phase", (Arg("cause", str, choices=("encoder", "blocked"), default="encoder",
                             doc="encoder: feedback lost, trips at once and after every power "
                                 "cycle until `clear`; blocked: the shaft is blocked, the "
                                 "alarm comes when the motor is asked to move"),),
          _lost_phase, AlarmCode.LOST_PHASE, "lost phase (alarm 1)"),
    Fault("load_step", (Arg("torque_nm", float, -100.0, 100.0, doc="external torque, + = CW"),),
          lambda d, a: d.set_disturbance(a["torque_nm"]), None,
          "a load torque step on the shaft (stays until `clear` or `load`)"),
    Fault("inertia", (Arg("kgm2", float, 0.0, 10.0, doc="load inertia at the motor shaft"),),
          lambda d, a: d.set_load(inertia=a["kgm2"]), None, "the load inertia changes"),
    Fault("supply_dip", (Arg("volts", float, 0.0, U.OVER_VOLTAGE_V, default=20.0,
                             doc="supply during the dip (below 24 V the drive is off)"),
                         Arg("seconds", float, 0.0, 3600.0, default=0.1, doc="dip length")),
          lambda d, a: d.supply_dip(a["volts"], a["seconds"]), None,
          "a supply dip; below 24 V a power cycle (2.5)"),
    Fault("power_cycle", (Arg("off_s", float, 0.0, 3600.0, default=0.5,
                              doc="seconds without power"),),
          lambda d, a: d.power_cycle(a["off_s"]), None,
          "power off, then on: clears a latched alarm (6.1)"),
)}

COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("ping", (), None, "the drive ids, commands and faults", changes=False,
            run_channel=channel.ping),
    Command("state", (), _state, "internal state: reference, error, current, bus, ...",
            changes=False),
    Command("outputs", (), _outputs, "JP3 outputs ALM, ONPOS/BKO, ZRI", changes=False),
    Command("analog", (Arg("volts", float, -K.ANALOG_INPUT_MAX_V, K.ANALOG_INPUT_MAX_V,
                           doc="JP3-2 (speed 600 rpm/V, torque 1 or 2 A/V, 4.2, 4.3)"),),
            _analog, "set the analog input"),
    Command("pulses", (Arg("count", int, -MAX_COUNT, MAX_COUNT, doc="signed pulses, + = CW"),
                       Arg("rate", float, 1e-3, K.PULSE_RATE_MAX_HZ, default=None,
                           doc="pulses per second [default: 500 kHz, the inputs' maximum]"),
                       Arg("seconds", float, 0.0, 86_400.0, default=None,
                           doc="spread over this long instead of a rate"),
                       Arg("format", str, choices=tuple(f.value for f in PulseFormat),
                           default=None, doc="[default: the format the drive decodes]")),
            _pulses, "feed a pulse train on JP3-3..6 (4 x GEAR_NUM pulses per rev, 4.1)"),
    Command("ena", (Arg("enabled", bool, doc="false: JP3-11 disables the drive (2.3)"),),
            _ena, "the ENA input"),
    Command("bus", (Arg("volts", float, 0.0, 200.0, doc="DC bus (over voltage above 80 V)"),),
            _bus, "set the supply / bus voltage"),
    *channel.world_commands(FAULTS, _load, _fault),
    Command("clear", (), _clear, "remove every fault cause (not the alarm)"),
    Command("power_cycle", (Arg("off_s", float, 0.0, 3600.0, default=0.0),), _power_cycle,
            "power off for off_s, then on (0: at once); clears a latched alarm (6.1)"),
)}

# ---------------------------------------------------------------------- the executor
class DriveControl(ChannelControl[VirtualDrive]):
    """Executes control requests on a set of DMM virtual drives, addressed by drive id
    (:class:`servobus.sim.core.control.ChannelControl` with this module's tables)."""

    commands = COMMANDS
    faults = FAULTS

    def drive_id(self, drive: VirtualDrive) -> int:
        return drive.drive_id

    # Python API: the same commands as keyword calls; each returns the reply, raising
    # ControlError instead of answering {"ok": false}.
    def analog(self, drive_id: int | None, volts: float) -> Reply:
        return self.call("analog", drive_id, volts=volts)

    def pulses(self, drive_id: int | None, count: int, *, rate: float | None = None,
               seconds: float | None = None, fmt: str | None = None) -> Reply:
        extra = {k: v for k, v in (("rate", rate), ("seconds", seconds), ("format", fmt))
                 if v is not None}
        return self.call("pulses", drive_id, count=count, **extra)

    def ena(self, drive_id: int | None, enabled: bool) -> Reply:
        return self.call("ena", drive_id, enabled=enabled)

    def outputs(self, drive_id: int | None = None) -> Reply:
        return self.call("outputs", drive_id)


def parse_args(command: Command, request: Mapping[str, Any]) -> dict[str, Any]:
    """Check a request's arguments against this module's tables; defaults filled in."""
    return channel.parse_args(command, request, FAULTS)
