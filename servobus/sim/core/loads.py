"""Loads to practise tuning on: the manual's sample load types as presets, and the keys that
set a load in a ``sim://`` URL, on ``servobus sim ... --load ...`` and in the control
channel's ``load`` command (docs/tuning.md).

Keys: ``load`` (a preset: ``screw``, ``direct``, ``belt``), ``inertia`` (load inertia over
rotor inertia), ``resonance`` (Hz of the compliant coupling; 0 = rigid) and ``load_torque``
(N m on the load side, against + like a weight being lifted). A preset sets inertia,
resonance and damping; a key given beside it overrides the preset's value.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from servobus.errors import InvalidValue
from servobus.sim.core import constants as K


@dataclass(frozen=True)
class Preset:
    """A sample load (DYN2 manual 5.2): inertia ratio, resonance (Hz, 0 = rigid), damping."""

    inertia: float
    resonance: float
    damping: float
    doc: str


#: Decisions (docs/tuning.md): a ball screw is light and stiff, a direct drive (a disc or an
#: arm on the shaft) rigid at the rotor's own inertia, a belt heavy and soft.
PRESETS: dict[str, Preset] = {
    "screw": Preset(2.0, 300.0, 0.1, "ball screw: light, stiff (300 Hz)"),
    "direct": Preset(1.0, 0.0, K.DEFAULT_DAMPING, "direct drive: rigid, load = rotor inertia"),
    "belt": Preset(5.0, 60.0, 0.1, "belt or pulley: heavy, compliant (60 Hz)"),
}

#: Key -> (lowest, highest) value; ``load`` is a preset name.
RANGES: dict[str, tuple[float, float]] = {
    "inertia": (0.0, 1000.0),
    "resonance": (0.0, K.RESONANCE_MAX_HZ),
    "load_torque": (-100.0, 100.0),
}
KEYS = ("load", *RANGES)


@dataclass(frozen=True)
class LoadSettings:
    """What a load request changes (None: left as it is)."""

    inertia: float | None = None
    resonance: float | None = None
    damping: float | None = None
    load_torque: float | None = None

    @property
    def empty(self) -> bool:
        return self == LoadSettings()


#: ``--plant`` / ``sim://...?plant=``: ``physics`` (the default: the servo loop, the motor and
#: its load) or ``ideal`` (the shaft follows the reference, no current, no alarms from the
#: loop, no load; a turning drive costs next to nothing: servobus.sim.core.engine,
#: docs/virtual-drive.md "The ideal plant").
PLANTS = ("physics", "ideal")


def load_settings(values: Mapping[str, object]) -> LoadSettings:
    """Check and combine the keys of :data:`KEYS` (values as text or numbers; others ignored).
    Raises InvalidValue naming the key at fault."""
    preset_name = values.get("load")
    fields: dict[str, float | None] = {}
    if preset_name is not None:
        preset = PRESETS.get(str(preset_name).lower())
        if preset is None:
            raise InvalidValue(f"load={preset_name!r}: one of {', '.join(PRESETS)}")
        fields = {"inertia": preset.inertia, "resonance": preset.resonance,
                  "damping": preset.damping}
    for key, (lo, hi) in RANGES.items():
        raw = values.get(key)
        if raw is None:
            continue
        try:
            value = float(raw)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise InvalidValue(f"{key}={raw!r} is not a number") from None
        if not lo <= value <= hi:
            raise InvalidValue(f"{key}={raw!r} is outside {lo:g}..{hi:g}")
        fields[key] = value
    return LoadSettings(**fields)


def split_load_options(options: Mapping[str, str]) -> tuple[dict[str, str], LoadSettings]:
    """A ``sim://`` URL's options without the load keys, and the load they describe."""
    rest = {k: v for k, v in options.items() if k not in KEYS}
    return rest, load_settings({k: v for k, v in options.items() if k in KEYS})
