"""Soft limits of the GUI's one-shot test motions (step tests, drive-generated waves),
checked before any motion command reaches the wire (issue 27).

A jog or constant speed is a lease that never passes a limit (servobus.machine.lease);
a step test (a relative move) and a wave are commands the drive runs by itself, so their
whole travel is checked first: the step's end point, the wave's offset +- amplitude (the
offset is the position where the wave starts; the amplitude in motor counts is the
family's ``wave_counts_per_unit`` times the drive's wave units, taken as a swing each way,
which covers the DMM manual's reading and the simulator's half-swing). Waves are not
leased: the drive runs them until the host stops them (Off, Stop, STOP ALL, the GUI's
shutdown); docs/safety.md.

Either motion is refused (OwnerError) while a lease of any owner or an auto-tune run holds
the axis: it would fight the streamed targets or the tuner's test moves. Stop it first.
Both are refused (PowerLostError) while the machine axis's possible power loss is not
acknowledged (issue 29).
"""

from __future__ import annotations

from servobus.errors import LimitError, OwnerError, PowerLostError
from servobus.gui.fleet import AxisHandle


def check_free(handle: AxisHandle, what: str) -> None:
    """OwnerError when a jog or constant speed runs on the axis; PowerLostError while a
    possible power loss is not acknowledged (the machine refuses its own motion then, and
    these commands reach the Axis directly)."""
    m = handle.machine_axis
    if m is not None and m.power_lost:
        raise PowerLostError(f"axis {m.name}: {what} refused: the drive may have lost power "
                             f"({m.power_lost_reason}); acknowledge it first, nothing was "
                             "sent")
    check_not_tuning(handle, what)
    lease = m.lease if m is not None else None
    if m is not None and lease is not None:
        raise OwnerError(f"axis {m.name}: {what} refused: {lease.owner} holds the axis "
                         "(jog or constant speed); stop it first, nothing was sent",
                         owner=lease.owner)


def check_not_tuning(handle: AxisHandle, what: str) -> None:
    """OwnerError while an auto-tune run (servobus.gui.autotune) moves the axis and writes
    its gains."""
    m = handle.machine_axis
    tuning = m.tuning_owner if m is not None else None
    if m is not None and tuning is not None:
        raise OwnerError(f"axis {m.name}: {what} refused: {tuning} is auto-tuning the axis; "
                         "cancel it first, nothing was sent", owner=tuning)


def check_travel(handle: AxisHandle, low: float, high: float, what: str) -> None:
    """LimitError (the machine axis's own check) when counts ``low``..``high`` of ``what``
    leave the axis's soft limits."""
    m = handle.machine_axis
    if m is None or m.limits is None:
        return
    try:
        for end in (low, high):
            m.check_target(m.to_user(end))
    except LimitError as exc:
        raise LimitError(f"{what}: {exc}") from None


def has_limits(handle: AxisHandle) -> bool:
    m = handle.machine_axis
    return m is not None and m.limits is not None


async def check_wave(handle: AxisHandle, amplitude: int) -> None:
    """A wave of ``amplitude`` (the drive's wave units) started here stays inside the
    limits (reads the position where it starts), and no lease runs."""
    check_free(handle, "a wave")
    if not has_limits(handle):
        return
    per_unit = handle.axis.family.wave_counts_per_unit
    if per_unit <= 0:
        raise LimitError(f"{handle.label}: the family gives no wave travel to check "
                         "against the soft limits; nothing was sent")
    offset = float(await handle.call(handle.axis.position()))
    swing = abs(amplitude) * per_unit
    check_travel(handle, offset - swing, offset + swing,
                 f"a wave of amplitude {amplitude} from here")


def check_step(handle: AxisHandle, start: float, distance: int) -> None:
    """A step test of ``distance`` counts from ``start`` counts ends inside the limits."""
    check_free(handle, "a step test")
    check_travel(handle, start, start + distance, f"a step of {distance} counts")
