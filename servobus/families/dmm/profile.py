"""Point-to-point profile math (DYN2 manual 7.4.1, DYN5 Appendix B). Pure: no I/O, no state.

The virtual drive's motion generator and the ``servobus profile`` command both use these
functions, so the table the command prints is the profile the simulator runs.

Profile: a trapezoid (or triangle for short moves) at the Max Speed / Max Accel figures,
then a moving-average smoothing filter on the speed (the manual's "smoothing filter applied to
the acceleration profile"; it curves the transitions into an S-curve). A moving average keeps
the distance exact and adds its window length to the total time.

Decision (the manuals give no number): the window is ``SMOOTHING_FRACTION`` of the trapezoid
time, capped at ``SMOOTHING_MAX_S`` and at the acceleration time so the peak acceleration of
the trapezoid is still reached. 1.5 % keeps the total within 2 % of Appendix B's 0.362 s
(the issue's bound is 5 %).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from servobus.axis.types import PtpCalculator
from servobus.families.dmm import units as U

SMOOTHING_FRACTION = 0.015
SMOOTHING_MAX_S = 0.050


@dataclass(frozen=True)
class PtpProfile:
    """Figures of one point-to-point move, in motor units (rpm, rpm/s, s, rev, counts)."""

    max_speed: int
    max_accel: int
    gear_num: int
    command: int
    gear_ratio: float
    speed_rpm: float  # profile (cruise) speed
    accel_rpm_s: float
    distance_counts: float
    peak_speed_rpm: float  # = speed_rpm unless the move is too short to reach it
    accel_time_s: float
    accel_distance_rev: float
    cruise_time_s: float
    trapezoid_time_s: float
    smoothing_s: float
    total_time_s: float  # trapezoid + smoothing window

    @property
    def distance_rev(self) -> float:
        return self.distance_counts / U.COUNTS_PER_REV

    def rows(self) -> list[tuple[str, str]]:
        """Human-readable table rows (label, value), Appendix B order."""
        return [
            ("Gear ratio", f"{self.gear_ratio:.4g}"),
            ("Maximum motor speed", f"{self.speed_rpm:.0f} rpm"),
            ("Maximum motor acceleration", f"{self.accel_rpm_s:.0f} rpm/s"),
            ("Motor movement", f"{self.distance_counts:.0f} counts = {self.distance_rev:.3f} rev"),
            ("Peak speed reached", f"{self.peak_speed_rpm:.0f} rpm"),
            ("Acceleration time", f"{self.accel_time_s:.3f} s"),
            ("Distance during acceleration", f"{self.accel_distance_rev:.2f} rev"),
            ("Constant speed travel time", f"{self.cruise_time_s:.3f} s"),
            ("Total profile time (trapezoid)", f"{self.trapezoid_time_s:.3f} s"),
            ("Smoothing window", f"{self.smoothing_s * 1000:.1f} ms"),
            ("Total S-curve time (smoothed)", f"{self.total_time_s:.3f} s"),
        ]

    def as_dict(self) -> dict[str, float | int]:
        return {
            "max_speed": self.max_speed, "max_accel": self.max_accel,
            "gear_num": self.gear_num, "command": self.command,
            "gear_ratio": self.gear_ratio, "speed_rpm": self.speed_rpm,
            "accel_rpm_s": self.accel_rpm_s, "distance_counts": self.distance_counts,
            "distance_rev": self.distance_rev, "peak_speed_rpm": self.peak_speed_rpm,
            "accel_time_s": self.accel_time_s, "accel_distance_rev": self.accel_distance_rev,
            "cruise_time_s": self.cruise_time_s, "trapezoid_time_s": self.trapezoid_time_s,
            "smoothing_s": self.smoothing_s, "total_time_s": self.total_time_s,
        }


def speed_counts_per_s(max_speed: int, gear_num: int) -> float:
    return U.rpm_to_counts_per_s(U.profile_speed_rpm(max_speed, gear_num))


def accel_counts_per_s2(max_accel: int, gear_num: int) -> float:
    return U.rpm_to_counts_per_s(U.profile_accel_rpm_s(max_accel, gear_num))


def trapezoid_time(distance: float, vmax: float, amax: float) -> tuple[float, float, float]:
    """(accel time, cruise time, peak speed) of a rest-to-rest trapezoid; any consistent units."""
    distance = abs(distance)
    if distance <= 0.0 or vmax <= 0.0 or amax <= 0.0:
        return 0.0, 0.0, 0.0
    ta = vmax / amax
    if amax * ta * ta >= distance:  # triangle: never reaches vmax
        ta = math.sqrt(distance / amax)
        return ta, 0.0, amax * ta
    return ta, (distance - amax * ta * ta) / vmax, vmax


def smoothing_window(trapezoid_s: float, accel_s: float) -> float:
    """Length of the moving-average smoothing filter for a move (see module docstring)."""
    return max(0.0, min(SMOOTHING_FRACTION * trapezoid_s, SMOOTHING_MAX_S, accel_s))


def ptp_profile(max_speed: int, max_accel: int, gear_num: int, command: int) -> PtpProfile:
    """The Appendix B calculation for one relative move of ``command`` units."""
    vmax = speed_counts_per_s(max_speed, gear_num)
    amax = accel_counts_per_s2(max_accel, gear_num)
    dist = U.command_to_counts(command, gear_num)
    ta, tc, vpeak = trapezoid_time(dist, vmax, amax)
    trap = 2 * ta + tc
    smooth = smoothing_window(trap, ta)
    return PtpProfile(
        max_speed=max_speed, max_accel=max_accel, gear_num=gear_num, command=command,
        gear_ratio=U.gear_ratio(gear_num),
        speed_rpm=U.profile_speed_rpm(max_speed, gear_num),
        accel_rpm_s=U.profile_accel_rpm_s(max_accel, gear_num),
        distance_counts=abs(dist),
        peak_speed_rpm=U.counts_per_s_to_rpm(vpeak),
        accel_time_s=ta,
        accel_distance_rev=0.5 * vpeak * ta / U.COUNTS_PER_REV,
        cruise_time_s=tc,
        trapezoid_time_s=trap,
        smoothing_s=smooth,
        total_time_s=trap + smooth,
    )


def profile_of(params: Mapping[str, int], command: int) -> PtpProfile:
    """:func:`ptp_profile` from the parameters by name (the Family's ``ptp_profile``)."""
    return ptp_profile(params["max_speed"], params["max_accel"], params["gear_num"], command)


#: The DMM families' point-to-point profile (DYN2 and DYN5 plan moves alike).
PTP = PtpCalculator(inputs=("max_speed", "max_accel", "gear_num"), compute=profile_of)


# ---------------------------------------------------------------- interpolation words
def pack_arc_word(plane: int, feedrate: int) -> int:
    """Make_CircularArc 5th word (example 8): plane * 256 + feedrate (feedrate -127..127)."""
    return plane * 256 + feedrate


def unpack_arc_word(word: int) -> tuple[int, int]:
    """Inverse of :func:`pack_arc_word`: (plane, feedrate) with feedrate in -127..127."""
    plane = (word + 128) // 256
    return plane, word - plane * 256
