"""What an Axis can do beyond move, speed, stop, status and parameters: one typed list.

A front end asks ``axis.supports(Capability.HOMING)`` (or calls the capability's method on
:class:`~servobus.axis.base.AsyncAxis`, which raises :class:`~servobus.errors.NotSupported`
before anything is sent where the axis lacks it); it never probes an Axis, its core or its
client with ``hasattr`` (issue 31; tests/axis/test_architecture.py enforces it).

Decision: two sources, one set. What a family's drives can do is declared once, in
``families/<f>/family.py`` (``Family.capabilities``, beside the profile that implements it in
``families/<f>/axis.py``). What depends on the connection is derived by the Axis itself:
a synchronised start (a bus with a broadcast start: ``sync_group()``), the drive trace and
the connector I/O (an in-process virtual drive), link statistics (a protocol client that
counts its transactions). ``AsyncAxis.capabilities`` is the union of the two. python-can's
``BusABC`` and moteus answer the same question the same way: a typed declaration, never
an attribute probe.

The values are the strings the GUI's JSON (``/api/axes``: ``features``) has always carried.
"""

from __future__ import annotations

from enum import StrEnum


class Capability(StrEnum):
    """One optional ability of an Axis (``AsyncAxis.capabilities``, ``supports``)."""

    #: Axes of one ``sync_group()`` start absolute moves with one trigger (``sync_move_to``).
    SYNC_START = "sync_start"
    #: The drive keeps a sample trace a host reads (``trace_buffer``): the virtual drives.
    DRIVE_TRACE = "drive_trace"
    #: Connector I/O a host drives (``virtual_io``): the virtual DMM drives.
    VIRTUAL_IO = "virtual_io"
    #: The protocol client counts its transactions (``link_stats``).
    LINK_STATS = "link_stats"
    #: Gains in the parameter table a step test can tune (the GUI's tuning page).
    TUNING = "tuning"
    #: A torque command whose speed limit the drive holds (DYN5 0x25-0x27).
    TORQUE_MODE = "torque_mode"
    #: Position targets streamed under a lease (``stream_profile``/``stream_to``).
    STREAM_TARGETS = "stream_targets"
    #: A cell a power cycle clears (``power_marker``): the machine detects a power loss by it.
    POWER_LOSS_DETECTION = "power_loss_detection"
    #: The family's homing run (``home``): a machine file's ``origin = "home"``.
    HOMING = "homing"
    #: Drive-generated square and sine test waves (``square_wave``, ``sine_wave``).
    WAVES = "waves"
    #: A configuration byte of the drive (``config``/``set_config``; DMM DYN2/DYN4).
    CONFIG = "config"
    #: The position here becomes the origin (``set_origin``).
    ORIGIN = "origin"
    #: The drive id can be read and assigned over the link (``read_id``/``assign_id``).
    DRIVE_ID = "drive_id"
    #: A latched alarm can be cleared from the host (``reset``).
    RESET = "reset"
    #: Moves in the drive's raw command units (``move_to_command``; DMM GEAR_NUM units).
    COMMAND_UNITS = "command_units"
    #: Cyclic I/O (an implicit EtherNet/IP connection; DYN5 section 5).
    CYCLIC_IO = "cyclic_io"
    #: A position every fixed cycle, taken by the drive on its own time base
    #: (``stream_cycles``; YZ-AIM EasyCan's 2 ms position cache with the sync signal).
    CYCLIC_POSITION = "cyclic_position"
    #: Axes of one ``sync_group()`` stream cyclic positions as one group: one cycle, one
    #: synchronisation signal for all (``stream_cycles_together``; YZ-AIM EasyCan's bus).
    CYCLIC_GROUP = "cyclic_group"

    @property
    def words(self) -> str:
        """For people: "power loss detection"."""
        return self.value.replace("_", " ")


#: Capabilities the connection gives rather than the family (a bus, a virtual drive, a
#: client): never in a ``Family.capabilities``, derived by the Axis.
CONNECTION_CAPABILITIES = frozenset({
    Capability.SYNC_START, Capability.DRIVE_TRACE, Capability.VIRTUAL_IO, Capability.LINK_STATS,
})
