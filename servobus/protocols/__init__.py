"""One package per wire protocol: codec, commands, client, virtual-drive front end, server.

Each package's ``__init__`` is light: it declares one frozen :class:`ProtocolSpec` as
``SPEC`` (its URL schemes and opener, its in-process virtual drive for ``sim://<name>``, its
CLI additions, sniff decoder, parameters, family), read by :mod:`servobus.axis.registry`;
every target is a ``"module:attribute"`` string, imported only when used. No package here
imports another one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ProtocolSpec:
    """What the shared layers (connect, sim://, CLI, sniff, GUI) may ask of one protocol.

    Targets are ``"module:attribute"`` (tests/axis/test_registry.py resolves every one).
    """

    #: The protocol's one name: its package, its sniff decoder's and its ``sim://`` name.
    name: str
    #: The family key of its drives (servobus.families): ``"dmm-dyn2"``, ``"yzaim"``.
    family: str
    #: ``async opener(url, *, drive_id, **options) -> AsyncAxis`` for its URL schemes.
    opener: str
    #: servobus's own URL schemes the opener serves.
    schemes: tuple[str, ...]
    #: Served by the same opener but not servobus's own (error messages do not list them):
    #: ``""`` (a bare serial port, ``/dev/ttyUSB0``) and pyserial's URL schemes.
    serial_schemes: tuple[str, ...] = ()
    #: The same opener for ``sim://<name>``: in-process virtual drives (None: none).
    sim: str | None = None
    #: Further names of the virtual drive (``sim://dyn2`` for ``sim://dyn232``).
    sim_aliases: tuple[str, ...] = ()
    #: Its command-line commands as data: a tuple of servobus.axis.cli_spec.Command
    #: (``servobus sim <name>``, ``servobus discover`` ...), built by servobus.cli.
    cli: str | None = None
    #: The sniff/decode decoder (servobus.sniff.Decoder).
    decoder: str | None = None
    #: The names of the family parameters this protocol reaches.
    params: str | None = None
    #: CLI shortcuts: option name -> URL template (``("can", "dyncan+{interface}://{channel}")``).
    shortcuts: tuple[tuple[str, str], ...] = ()
    #: Schemes (of ``schemes`` or ``serial_schemes``) whose axes need no event loop between
    #: calls - one connection that speaks only when asked, no task left running - so the
    #: sync facade may run their calls on the caller's thread (servobus.axis.inline).
    inline_schemes: tuple[str, ...] = ()
    #: What carries its frames, for advice that names only what applies (a DriveTimeout on
    #: CAN says nothing of --baud): ``"serial"`` (a baud rate), ``"can"`` (the bus bitrate,
    #: set on the interface) or ``"network"`` (an IP address).
    link: str = "serial"

    @classmethod
    def conventional(cls, name: str, family: str, **fields: Any) -> ProtocolSpec:
        """The spec of a package laid out as every ``servobus/protocols/<name>/`` is: targets
        by convention - ``opener:open_axis`` for scheme ``<name>``, ``inprocess:open_sim_axis``,
        ``cli:COMMANDS``, ``sniff:DECODER``, ``commands:REACHABLE_PARAMS`` - unless ``fields``
        name another (any field of the spec)."""
        base = f"servobus.protocols.{name}"
        conventions: dict[str, Any] = {
            "opener": f"{base}.opener:open_axis", "schemes": (name,),
            "sim": f"{base}.inprocess:open_sim_axis", "cli": f"{base}.cli:COMMANDS",
            "decoder": f"{base}.sniff:DECODER", "params": f"{base}.commands:REACHABLE_PARAMS"}
        return cls(name=name, family=family, **{**conventions, **fields})

    @property
    def sim_names(self) -> tuple[str, ...]:
        """Every ``sim://<name>`` this protocol's virtual drive answers to."""
        return (self.name, *self.sim_aliases) if self.sim else ()
