"""The tuner's plant on simulated time: a virtual drive's core, stepped period by period.

The tests and ``python -m benchmarks tune`` run :class:`servobus.tune.tuner.Tuner` on it
without a wall clock: a test move runs exactly its seconds of control periods. With
``trace=False`` it samples as a link polls (``poll_hz``, position and current only, no
position error): the tuner's poll-only path. The gains are written as the family's protocol
writes them (DMM: the parameter, to EEPROM; YZ-AIM: the register, RAM).
"""

from __future__ import annotations

from typing import Protocol

from servobus.axis.types import MOVING_RPM, Family, ParamInfo, TuningProfile
from servobus.errors import ArgumentRangeError
from servobus.families.dmm.family import DYN2
from servobus.families.yzaim import registers as yz
from servobus.families.yzaim.family import YZAIM
from servobus.sim.core import constants as K
from servobus.sim.core.loads import LoadSettings
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.yzaim import physics as phys
from servobus.sim.yzaim.motor import YzaimMotor
from servobus.tune.record import Record

#: A link's poll rate for the poll-only path: a DYN232 line reads a position and a current
#: in about 10 ms at 38,400 baud (docs/performance.md).
POLL_HZ = 100.0
#: Polls in a row below MOVING_RPM that count as standing still.
SETTLED_POLLS = 5


class _Core(Protocol):
    time: float

    def advance_to(self, t: float) -> None: ...


class SteppedPlant:
    """A :class:`servobus.tune.plant.Plant` over a DMM ``VirtualDrive`` or a ``YzaimMotor``."""

    def __init__(self, core: VirtualDrive | YzaimMotor, *, trace: bool = True,
                 poll_hz: float = POLL_HZ) -> None:
        self.core = core
        self.family: Family = DYN2 if isinstance(core, VirtualDrive) else YZAIM
        profile = self.family.tuning
        if profile is None:
            raise ArgumentRangeError(f"{self.family.title} has no tuning profile")
        self.profile: TuningProfile = profile
        self.trace = trace
        self.source = "trace" if trace else "poll"
        self.rate_hz = float(K.CONTROL_HZ) if trace else poll_hz
        self.moves = 0
        self.stops = 0
        self.gain_writes: list[tuple[str, int]] = []
        self.saved = 0
        #: Called after every control period of a test move (tests inject faults here).
        self.during_move: list[object] = []

    @classmethod
    def dmm(cls, load: LoadSettings, **kw: object) -> SteppedPlant:
        drive = VirtualDrive(1)
        drive.set_mechanics(load)
        drive.advance(0.01)
        return cls(drive, **kw)  # type: ignore[arg-type]

    @classmethod
    def yzaim(cls, load: LoadSettings, **kw: object) -> SteppedPlant:
        motor = YzaimMotor(1)
        motor.drive.set_mechanics(load)
        motor.advance(0.01)
        return cls(motor, **kw)  # type: ignore[arg-type]

    @property
    def counts_per_rev(self) -> int:
        return self.family.counts_per_rev

    def param_info(self, name: str) -> ParamInfo:
        return self.family.param(name)

    async def read_gain(self, name: str) -> int:
        core = self.core
        if isinstance(core, VirtualDrive):
            return core.get_param(name)
        return core.registers()[name]

    async def write_gain(self, name: str, value: int) -> None:
        core = self.core
        self.gain_writes.append((name, value))
        if isinstance(core, VirtualDrive):
            if not core.set_param(name, value):
                raise ArgumentRangeError(f"the drive refused {name}={value}")
        else:
            core.write_words(yz.BY_NAME[name].address, [value])

    async def position(self) -> int:
        core = self.core
        return core.position

    def _sample(self) -> tuple[float, float, float]:
        core = self.core
        if isinstance(core, VirtualDrive):
            return core.shaft_position, core.position_error, core.current_a
        d = core.drive
        return core.position, d.position_error / phys.CORE_PER_COUNT, d.current_a

    def alarm(self) -> tuple[int, str]:
        core = self.core
        code = int(core.alarm) if isinstance(core, VirtualDrive) else core.alarm.code
        return code, self.family.alarm_text(code)

    async def test_move(self, target: int, seconds: float) -> Record:
        core = self.core
        start = float(await self.position())
        self.moves += 1
        if isinstance(core, VirtualDrive):
            per_command = 16384 / core.get_param("gear_num")  # DYN2 7.4.1
            command = round(target / per_command)
            core.move_absolute(command)
            goal = command * per_command
        else:
            # incremental from the motor's own target: an absolute 0 clears the position (5.2)
            step = target - core.target
            if step:
                core.write_words(yz.PAIR_BY_NAME["incremental_position"].low, yz.split32(step))
            goal = float(target)
        t0 = core.time
        every = max(1, round(K.CONTROL_HZ / self.rate_hz))
        times: list[float] = []
        pos: list[float] = []
        err: list[float] = []
        cur: list[float] = []
        for k in range(1, round(seconds * K.CONTROL_HZ) + 1):
            core.advance_to(t0 + k * K.CONTROL_DT)
            for hook in self.during_move:
                hook(self, k)  # type: ignore[operator]
            if k % every == 0:
                p, e, c = self._sample()
                times.append(k * K.CONTROL_DT)
                pos.append(p)
                err.append(e)
                cur.append(c)
        code, text = self.alarm()
        return Record(times, pos, err if self.trace else None, cur, start, goal, code, text)

    async def settle(self, timeout: float) -> None:
        core = self.core
        still = 0
        end = core.time + timeout
        while core.time < end and still < SETTLED_POLLS:
            core.advance_to(core.time + 1.0 / POLL_HZ)
            still = still + 1 if abs(core.speed_rpm) < MOVING_RPM else 0

    async def stop(self) -> None:
        self.stops += 1
        core = self.core
        if isinstance(core, VirtualDrive):
            core.turn_const_speed(0)
        else:
            core.emergency_stop()

    async def save(self) -> None:
        if isinstance(self.core, YzaimMotor):
            self.core.write_words(yz.BY_NAME["save_flag"].address, [1])
            self.saved += 1

    def rotor_amps_per_accel(self) -> float | None:
        """The bare rotor's A per rev/s^2 (J / Kt x 2 pi): the motor model is known here."""
        m = self.core.model if isinstance(self.core, VirtualDrive) else self.core.drive.model
        return m.rotor_inertia_kgm2 * 2 * 3.141592653589793 / m.torque_constant_nm_a
