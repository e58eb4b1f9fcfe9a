"""``sim://<protocol>``: in-process virtual drives of any protocol (docs/axis.md).

The registry names this module for the scheme (``BUILTIN_SCHEMES``), so a host client never
imports the simulator unless a ``sim://`` URL is opened. Each protocol's spec names the
opener of its in-process virtual drive (``sim``: ``sim://dyn232``, ``sim://dyncan``, ...).

Options every protocol's virtual drive takes: ``ids=1,2,3`` (default: the id asked for, else
the protocol's factory id), ``fast=1`` (no wire pacing), ``state=FILE`` (EEPROM kept in a
JSON file), ``model=NAME`` (motor/drive model), and the load its motors drive:
``load=screw|direct|belt``, ``inertia`` (load / rotor inertia), ``resonance`` (Hz) and
``load_torque`` (N m), e.g. ``sim://dyn232?load=belt&inertia=10`` (servobus.sim.core.loads,
docs/tuning.md).

Every ``sim://`` axis reads its virtual drives' 4 kHz trace with ``trace_buffer()``
(servobus.sim.core.capture), whatever the protocol; the axes of the DMM families reach their
drives' JP3 inputs and outputs with ``virtual_io()`` (servobus.sim.dmm.virtual_io).
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from servobus.axis import registry
from servobus.axis.url import DriveUrl
from servobus.errors import ArgumentRangeError
from servobus.sim.core import capture
from servobus.sim.core.loads import PLANTS, split_load_options
from servobus.sim.core.motor import EngineShaft
from servobus.sim.dmm import virtual_io
from servobus.sim.dmm.drive import VirtualDrive

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis

DEFAULT_PROTOCOL = "dyn232"


def sim_protocols() -> dict[str, str]:
    """Virtual-drive name -> opener, from every protocol package's ``SIM`` table."""
    return registry.provided("SIM")


async def open_axis(url: DriveUrl, *, drive_id: int | None = None, **keywords: Any) -> AsyncAxis:
    name = url.target.strip("/").lower() or DEFAULT_PROTOCOL
    target = sim_protocols().get(name)
    if target is None:
        raise ArgumentRangeError(
            f"no virtual drive {name!r} in {url.raw!r}; known: sim://"
            + ", sim://".join(sorted(sim_protocols())))
    options, load = split_load_options(url.options)
    plant = options.pop("plant", "physics")
    if plant not in PLANTS:
        raise ArgumentRangeError(f"plant={plant} in {url.raw!r}: give one of "
                                 f"{', '.join(PLANTS)}")
    ideal = plant == "ideal"
    if ideal and not load.empty:
        raise ArgumentRangeError(f"plant=ideal has no mechanics: no load keys in {url.raw!r}")
    url = dataclasses.replace(url, options=MappingProxyType(options))
    opener = registry.load(target)
    with capture.collecting() as traced:  # the virtual drives (or motors) this axis talks to
        axis: AsyncAxis = await opener(url, drive_id=drive_id, **keywords)
    for made in traced:
        if isinstance(made.drive, EngineShaft):
            if ideal:
                made.drive.set_ideal(True)
            elif not load.empty:
                made.drive.set_mechanics(load)
    if traced and axis.capture_source is None:
        axis.capture_source = capture.SimCapture(traced)  # trace_buffer(): their 4 kHz trace
    if traced and axis.io_source is None and virtual_io.has_jp3(axis.family.name):
        drives = [t.drive for t in traced if isinstance(t.drive, VirtualDrive)]
        axis.io_source = virtual_io.SimIoSource(drives)  # their JP3 I/O
    return axis
