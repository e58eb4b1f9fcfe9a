"""The synchronous Machine: the async core on a private loop thread (as servobus.axis.sync).

Every method mirrors the async one explicitly, with its types; each call runs on the
machine's loop thread and blocks on the result.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import TYPE_CHECKING

from servobus.axis.sync import Axis, LoopThread
from servobus.machine.lease import DEFAULT_TTL_S, Lease
from servobus.machine.machine import (
    AsyncMachine,
    TogetherReport,
    open_machine_async,
    open_url_machine_async,
)

if TYPE_CHECKING:
    from servobus.axis.types import AxisStatus, Family
    from servobus.machine.axis import AsyncMachineAxis
    from servobus.tune.tuner import Trial, TuneResult


class MachineAxis:
    """One axis of a :class:`Machine`, in user units (AsyncMachineAxis, synchronously)."""

    def __init__(self, core: AsyncMachineAxis, runner: LoopThread) -> None:
        self._core = core
        self._runner = runner

    @property
    def core(self) -> AsyncMachineAxis:
        """The async axis (for use on the machine's loop thread only)."""
        return self._core

    @property
    def name(self) -> str:
        return self._core.name

    @property
    def unit(self) -> str:
        return self._core.unit

    @property
    def speed_unit(self) -> str:
        return self._core.speed_unit

    @property
    def limits(self) -> tuple[float, float] | None:
        return self._core.limits

    @property
    def url(self) -> str:
        return self._core.url

    @property
    def drive_id(self) -> int | None:
        return self._core.drive_id

    @property
    def online(self) -> bool:
        return self._core.online

    @property
    def last_error(self) -> BaseException | None:
        return self._core.last_error

    @property
    def last_good(self) -> float | None:
        """``time.time()`` of the last call that succeeded (AsyncMachineAxis.last_good)."""
        return self._core.last_good

    @property
    def interrupted(self) -> str | None:
        """The motion the last link drop interrupted (never re-sent), or None."""
        return self._core.interrupted

    @property
    def power_lost(self) -> bool:
        """The drive may have lost power: motion is refused until :meth:`acknowledge`."""
        return self._core.power_lost

    @property
    def power_lost_reason(self) -> str | None:
        return self._core.power_lost_reason

    @property
    def origin_pending(self) -> bool:
        return self._core.origin_pending

    def acknowledge(self) -> None:
        """Clear the power-loss and interrupted-motion flags (nothing is sent)."""
        self._runner.run(self._core.acknowledge())

    @property
    def family(self) -> Family | None:
        return self._core.family

    @property
    def protocol(self) -> str | None:
        return self._core.protocol

    @property
    def axis(self) -> Axis | None:
        """The underlying Axis (sync, sharing the machine's loop), None while offline."""
        core = self._core.axis
        return None if core is None else Axis(core, self._runner, owns_runner=False)

    def to_counts(self, user: float) -> int:
        return self._core.to_counts(user)

    def to_user(self, counts: float) -> float:
        return self._core.to_user(counts)

    def check_target(self, target: float) -> float:
        return self._core.check_target(target)

    def counts(self) -> int:
        return self._runner.run(self._core.counts())

    def position(self) -> float:
        return self._runner.run(self._core.position())

    def speed(self) -> float:
        return self._runner.run(self._core.speed())

    def status(self) -> AxisStatus:
        return self._runner.run(self._core.status())

    def tune(self, distance: int, *, owner: str = "api", vibration_limit: float | None = None,
             trace: bool = True, save: bool = False, goal: str = "settling",
             on_trial: Callable[[Trial], None] | None = None) -> TuneResult:
        """A tuning run (:meth:`servobus.machine.axis.MachineAxis.tune`)."""
        return self._runner.run(self._core.tune(distance, owner=owner,
                                                vibration_limit=vibration_limit, trace=trace,
                                                save=save, goal=goal,
                                                on_trial=on_trial))

    def revert_gains(self, original: Mapping[str, int]) -> dict[str, int]:
        """A tuning run's kept gains back (MachineAxis.revert_gains)."""
        return self._runner.run(self._core.revert_gains(original))

    def restore_gains(self) -> dict[str, int]:
        """A killed tuning run's kept gains back (MachineAxis.restore_gains)."""
        return self._runner.run(self._core.restore_gains())

    def move_to(self, target: float, *, wait: bool = False, timeout: float | None = None) -> None:
        self._runner.run(self._core.move_to(target, wait=wait, timeout=timeout))

    def move_by(self, distance: float, *, wait: bool = False,
                timeout: float | None = None) -> None:
        self._runner.run(self._core.move_by(distance, wait=wait, timeout=timeout))

    def turn(self, speed: float | None = None, *, owner: str = "api",
             ttl: float = DEFAULT_TTL_S) -> None:
        """Constant speed; a lease ending ``ttl`` s after the last call unless the axis is
        ``continuous`` (AsyncMachineAxis.turn)."""
        self._runner.run(self._core.turn(speed, owner=owner, ttl=ttl))

    def jog(self, speed: float | None = None, *, owner: str = "api",
            ttl: float = DEFAULT_TTL_S) -> None:
        """Start or renew a leased motion (AsyncMachineAxis.jog)."""
        self._runner.run(self._core.jog(speed, owner=owner, ttl=ttl))

    def renew(self, owner: str, ttl: float = DEFAULT_TTL_S) -> bool:
        """Keep ``owner``'s lease alive; False when it has ended (AsyncMachineAxis.renew)."""
        return self._runner.run(self._renew(owner, ttl))

    async def _renew(self, owner: str, ttl: float) -> bool:
        return self._core.renew(owner, ttl)  # on the loop thread, beside the streamer

    def release(self, owner: str) -> None:
        self._runner.run(self._core.release(owner))

    @property
    def lease(self) -> Lease | None:
        return self._core.lease

    @property
    def continuous(self) -> bool:
        return self._core.continuous

    def stop(self) -> None:
        self._runner.run(self._core.stop())

    def enable(self) -> None:
        self._runner.run(self._core.enable())

    def disable(self) -> None:
        self._runner.run(self._core.disable())

    def reset(self) -> None:
        self._runner.run(self._core.reset())

    def set_origin(self) -> None:
        self._runner.run(self._core.set_origin())

    def home(self) -> None:
        """The drive's own homing (AsyncMachineAxis.home); NotSupported saying why."""
        self._runner.run(self._core.home())

    def apply_profile(self) -> dict[str, int]:
        """The file's speed and accel as the drive's move profile, written only where the
        drive differs (AsyncMachineAxis.apply_profile); the parameters written."""
        return self._runner.run(self._core.apply_profile())

    def wait_idle(self, timeout: float | None = None) -> AxisStatus:
        return self._runner.run(self._core.wait_idle(timeout))

    def __repr__(self) -> str:
        return repr(self._core).replace("AsyncMachineAxis", "MachineAxis", 1)


class Machine:
    """A machine file's axes by name, synchronously (see AsyncMachine)."""

    def __init__(self, core: AsyncMachine, runner: LoopThread) -> None:
        self._core = core
        self._runner = runner
        self._axes = {name: MachineAxis(a, runner) for name, a in core.axes.items()}

    @property
    def core(self) -> AsyncMachine:
        return self._core

    @property
    def name(self) -> str:
        return self._core.name

    @property
    def path(self) -> Path | None:
        return self._core.path

    @property
    def axes(self) -> Mapping[str, MachineAxis]:
        return MappingProxyType(self._axes)

    def __getitem__(self, name: str) -> MachineAxis:
        self._core[name]  # the one error naming the axes
        return self._axes[name]

    @property
    def origins_skipped(self) -> tuple[str, ...]:
        return self._core.origins_skipped

    def stop_all(self) -> dict[str, BaseException | None]:
        return self._runner.run(self._core.stop_all())

    def move_together(self, targets: Mapping[str, float], *, wait: bool = False,
                      timeout: float | None = None) -> TogetherReport:
        return self._runner.run(self._core.move_together(targets, wait=wait, timeout=timeout))

    def close(self, *, stop: bool = True) -> None:
        """Stop every axis (unless ``stop=False``), close the links and the loop thread;
        idempotent."""
        if self._runner.stopped:
            return
        try:
            self._runner.run(self._core.close(stop=stop))
        finally:
            self._runner.stop()

    def __enter__(self) -> Machine:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return repr(self._core).replace("AsyncMachine", "Machine", 1)


def open_machine(path: str | Path | None = None, *, retry: bool = False,
                 only: Collection[str] | None = None, origins: bool = True) -> Machine:
    """Synchronous :func:`open_machine_async` on a private loop thread."""
    runner = LoopThread("servobus-machine")
    try:
        core = runner.run(open_machine_async(path, retry=retry, only=only, origins=origins))
    except BaseException:
        runner.stop()
        raise
    return Machine(core, runner)


def open_url_machine(url: str, drive_ids: Sequence[int | None] = (None,), *,
                     retry: bool = False) -> Machine:
    """Synchronous :func:`open_url_machine_async`: a bare drive URL as a machine of one
    axis per id, on a private loop thread (a lease's streamer runs there between calls)."""
    runner = LoopThread("servobus-machine")
    try:
        core = runner.run(open_url_machine_async(url, drive_ids, retry=retry))
    except BaseException:
        runner.stop()
        raise
    return Machine(core, runner)
