"""Dyn5Axis: the DMM profile of a DYN5, over its Parameter object (docs/enip.md).

A DYN5 runs the DMM profile (:class:`~servobus.families.dmm.axis.DmmAxis`) through the
instances of its Parameter object (class 0x0F, attribute 1; DYN5 EtherNet/IP Specification
1.1A, 4.3/4.4): each profile action is one instance write, the status is the status word
0x02, the readouts 0x1D/0x1E/0x1F. A wire gives two primitives, :meth:`read_instance` and
:meth:`_write_instance` (EtherNet/IP explicit messaging:
:mod:`servobus.protocols.enip.axis`), and the peak current.

* GEAR_NUM is RAM (4.1): origin (0x03 = 0xFFFF) and Reset (0x21 = 0xABCD) reload it, so the
  axis forgets it there and reads it again before the next move.
* Current: 0x1F counts 2000 = 100 % of the drive's peak current, positive = CCW (4.4); the
  Axis gives amperes positive towards increasing position (CW), so the sign flips. The peak
  current is not readable over the wire: :attr:`peak_current_a` scales it.
* Torque mode (0x25/0x26/0x27) and the power marker (0x01, memory test) are the DYN5's own.
"""

from __future__ import annotations

from abc import abstractmethod

from servobus import checks
from servobus.axis.types import AxisStatus, Family, ParamInfo
from servobus.errors import ArgumentRangeError, NotSupported
from servobus.families.dmm.axis import Action, DmmAxis, Readout
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.family import DYN5, PARAM_INSTANCES, Dyn5Status, axis_status
from servobus.families.dyn5.params import Instance

_I = dyn5.BY_NAME
#: The instance of each profile action, and the value written where it takes none.
ACTIONS: dict[Action, tuple[Instance, int | None]] = {
    Action.MOVE_ABSOLUTE: (_I["go_absolute_pos"], None),
    Action.MOVE_RELATIVE: (_I["go_relative_pos"], None),
    Action.TURN: (_I["turn_const_speed"], None),
    Action.SQUARE_WAVE: (_I["square_wave_amplitude"], None),
    Action.SINE_WAVE: (_I["sine_wave_amplitude"], None),
    Action.WAVE_FREQUENCY: (_I["ss_frequency"], None),
    Action.SET_ORIGIN: (_I["set_abs_origin"], dyn5.ORIGIN_KEY),
    Action.ENABLE: (_I["sw_enable"], dyn5.ENABLE),
    Action.DISABLE: (_I["sw_enable"], dyn5.DISABLE),
    Action.RESET: (_I["drive_reset"], dyn5.RESET_KEY),
}
READOUTS: dict[Readout, Instance] = {
    Readout.POSITION: _I["motor_position"],
    Readout.SPEED: _I["motor_speed"],
    Readout.TORQUE: _I["motor_torque"],
}
#: Actions after which the drive reloads its RAM values, GEAR_NUM included (4.4).
RELOADS = frozenset({Action.SET_ORIGIN, Action.RESET})


def _range(inst: Instance) -> tuple[int, int]:
    assert inst.minimum is not None and inst.maximum is not None
    return inst.minimum, inst.maximum


class Dyn5Axis(DmmAxis[int]):
    """One DYN5 through its Parameter object (module docstring)."""

    command_range = _range(_I["go_absolute_pos"])

    # ------------------------------------------------------------- the wire's primitives
    @abstractmethod
    async def read_instance(self, key: int | str, *, timeout: float | None = None,
                            retries: int | None = None) -> int:
        """Attribute 1 of a Parameter instance (number or table name), signed where the
        instance's range is."""

    @abstractmethod
    async def _write_instance(self, inst: Instance, value: int) -> None:
        """Set attribute 1 of ``inst`` to ``value`` (checked against the table)."""

    @property
    @abstractmethod
    def peak_current_a(self) -> float:
        """The drive's peak current (A), which scales the torque instances."""

    async def write_instance(self, key: int | str, value: int) -> None:
        """Set attribute 1 of a known instance; the value is checked against the table first."""
        inst = dyn5.instance(key)
        await self._write_instance(inst, inst.check(value))

    # ------------------------------------------------------------- DmmAxis hooks
    @property
    def family(self) -> Family:
        return DYN5

    def _action_value(self, action: Action, value: int) -> tuple[Instance, int]:
        inst, fixed = ACTIONS[action]
        return inst, inst.check(value if fixed is None else fixed)

    async def _send(self, action: Action, value: int = 0) -> None:
        await self._write_instance(*self._action_value(action, value))
        if action in RELOADS:
            self._gear_num = None

    def _check_action(self, action: Action, value: int) -> None:
        self._action_value(action, value)

    async def _read_value(self, readout: Readout) -> int:
        return await self.read_instance(READOUTS[readout].number)

    async def _read_status(self) -> int:
        return await self.status_word()

    def _status_busy(self, status: int) -> bool:
        return Dyn5Status.from_word(status).motion_busy

    def _axis_status(self, status: int, speed_rpm: float | None) -> AxisStatus:
        return axis_status(status, speed_rpm)

    def _torque_amps(self, raw: int) -> float:
        """0x1F: 2000 = peak current, positive = CCW; the Axis's sign is CW."""
        return 0.0 - dyn5.torque_to_amps(raw, self.peak_current_a)

    async def _write_param(self, name: str, value: int) -> None:
        await self._write_instance(self._param_instance(name), value)

    async def status_word(self) -> int:
        return await self.read_instance(_I["drive_status"].number)

    # ------------------------------------------------------------- parameters
    def parameters(self) -> tuple[ParamInfo, ...]:
        return DYN5.params

    def _param_instance(self, name: str) -> Instance:
        self.param_info(checks.param_name(name))
        return PARAM_INSTANCES[name]

    async def read_param(self, name: str) -> int:
        return await self.read_instance(self._param_instance(name).number)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        return self._param_instance(name).check(checked)

    # ------------------------------------------------------------- the DYN5's own
    async def home(self) -> None:
        """The DYN5 runs no homing of its own: after power-up or Reset it reports its
        absolute position without moving (DYN5 manual 4.4, 0x21 and "Motor Absolute
        Position"); nothing is sent."""
        raise NotSupported(f"a {self.family.title} runs no homing of its own: after a "
                           "power-up or Reset it reports its absolute position without "
                           "moving: set the zero where the axis stands "
                           "(origin: Set ABS Origin), then move to 0", family=self.family.name)

    async def power_marker(self, token: int | None = None) -> int | None:
        """Instance 0x01, the memory test object (4.4): RAM that "will be lost after power
        cycle or Reset", 0 after power-up. The machine leaves a non-zero token there and
        reads it after its link came back: 0 means the drive lost power (or was reset)."""
        if token is not None:
            await self.write_instance("memory_test", token)
        return await self.read_instance("memory_test")

    async def set_torque_mode(self, torque: bool) -> None:
        """0x25: torque mode (True) or position/speed mode (False); the torque command
        restarts at 0."""
        await self.write_instance("command_mode",
                                  dyn5.TORQUE_MODE if torque else dyn5.POSITION_SPEED_MODE)

    async def torque_mode(self) -> bool:
        return await self.read_instance(_I["command_mode"].number) == dyn5.TORQUE_MODE

    async def torque(self, amps: float) -> None:
        """Torque-mode current command in amperes, positive towards increasing position
        (0x26: 2000 = peak current, positive = CW); clamped to +-peak.

        The drive delivers it only below the torque-mode speed limit (parameter
        ``torque_speed_limit``, 0x27): there its speed loop clamps the torque and holds the
        limit, so the current read back falls to what the load takes (docs/enip.md)."""
        if isinstance(amps, bool) or not isinstance(amps, int | float) or amps != amps:
            raise ArgumentRangeError(f"amps must be a number, got {amps!r}")
        await self.write_instance("torque_command",
                                  dyn5.amps_to_torque(float(amps), self.peak_current_a))
