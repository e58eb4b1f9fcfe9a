"""The drive as the tuner sees it: gains, a leased test move, a stop (no protocol by name)."""

from __future__ import annotations

from typing import Protocol

from servobus.axis.types import ParamInfo, TuningProfile
from servobus.tune.record import Record


class Plant(Protocol):
    """What :class:`servobus.tune.tuner.Tuner` drives.

    ``test_move`` moves to the absolute ``target`` (counts) and records ``seconds`` of it
    from the command on; each one is leased (it stops on its own when the tuner stops
    renewing: on an abort, a Ctrl-C or a lost link). ``source`` is ``"trace"`` (the drive's
    own samples) or ``"poll"`` (what the link reads), ``rate_hz`` its sample rate."""

    profile: TuningProfile
    source: str
    rate_hz: float

    def param_info(self, name: str) -> ParamInfo: ...

    async def read_gain(self, name: str) -> int: ...

    async def write_gain(self, name: str, value: int) -> None: ...

    async def position(self) -> int: ...

    async def test_move(self, target: int, seconds: float) -> Record: ...

    async def stop(self) -> None: ...

    async def settle(self, timeout: float) -> None:
        """Until the motor stands still (or ``timeout`` s): each test move starts at rest."""
        ...

    async def save(self) -> None:
        """Keep the gains over a power cycle (RAM_SAVE_COMMAND families only)."""
        ...

    def rotor_amps_per_accel(self) -> float | None:
        """Current (A) per rev/s^2 of the bare rotor, where the motor model is known: the
        inertia test's ratio is the load's over it. None: the ratio is not known."""
        ...
