"""The control channel's language, whatever drive serves it: requests and replies are JSON
objects (:data:`Reply`), a refused request a :class:`ControlError` of one of
:data:`ERROR_KINDS`, a command's or a fault's argument an :class:`Arg` (type, range,
choices, default), a command a :class:`Command`, and :class:`ChannelControl` the executor
that checks a request against a family's tables and runs it on the drive its ``id`` names.
The commands and faults a family's virtual drive takes are its own
(``servobus.sim.dmm.control``: JP3 I/O, DMM faults; ``servobus.sim.yzaim.control``: YZ-AIM
supply, battery, stall); docs/sim-control.md lists them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

from servobus.errors import ServobusError
from servobus.sim.core import loads

Reply = dict[str, Any]


class ControlError(ServobusError):
    """A request the channel refuses; ``kind`` names the class of problem (see ERROR_KINDS)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


#: Error kinds in replies ``{"ok": false, "kind": ..., "error": ...}``.
ERROR_KINDS = {
    "malformed": "the line is not a JSON object",
    "too_long": "the line is longer than the channel accepts (the rest of it is skipped)",
    "unknown_command": "cmd is missing or not a command",
    "unknown_id": "no drive with that id (or id missing with several drives)",
    "bad_argument": "an argument is missing, unknown, of the wrong type or out of range",
    "busy": "the channel serves its maximum number of connections",
}

_REQUIRED = object()


@dataclass(frozen=True)
class Arg:
    """One argument: JSON type (float, int, bool, str), range or choices, default."""

    name: str
    kind: type
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    default: object = _REQUIRED
    doc: str = ""

    @property
    def required(self) -> bool:
        return self.default is _REQUIRED

    def parse(self, raw: object) -> object:
        if self.kind is bool:
            if not isinstance(raw, bool):
                raise ControlError("bad_argument", f"{self.name} must be true or false")
            return raw
        if self.kind is str:
            if not isinstance(raw, str) or (self.choices and raw not in self.choices):
                raise ControlError("bad_argument",
                                   f"{self.name} must be one of {', '.join(self.choices)}")
            return raw
        if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
            raise ControlError("bad_argument", f"{self.name} must be a finite number")
        value: float = raw
        if self.kind is int:
            if value != int(value):
                raise ControlError("bad_argument", f"{self.name} must be an integer")
            value = int(value)
        if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            raise ControlError("bad_argument",
                               f"{self.name} {raw} is outside {self.lo:g}..{self.hi:g}")
        return value


class FaultInfo(Protocol):
    """What a client shows of a fault a channel can inject: name, arguments, what it does."""

    @property
    def name(self) -> str: ...

    @property
    def args(self) -> tuple[Arg, ...]: ...

    @property
    def doc(self) -> str: ...


#: A channel's faults by name.
FaultTable = Mapping[str, FaultInfo]


Target = TypeVar("Target")


@dataclass(frozen=True)
class Command(Generic[Target]):
    """A command on one drive (``run``), or on the channel itself (``run_channel``: no id).
    Handlers get the executor, the drive (``run`` only) and the parsed arguments."""

    name: str
    args: tuple[Arg, ...]
    run: Callable[[Any, Target, dict[str, Any]], Reply] | None
    doc: str
    changes: bool = True  # False: a read (servers log it at debug level only)
    run_channel: Callable[[Any, dict[str, Any]], Reply] | None = None


_ENVELOPE = frozenset({"cmd", "id", "seq"})


def parse_args(command: Command[Any], request: Mapping[str, Any],
               faults: FaultTable) -> dict[str, Any]:
    """Check a request's arguments against the tables; defaults filled in (a ``fault``
    request also takes its fault's arguments)."""
    specs = {a.name: a for a in command.args}
    if command.name == "fault" and isinstance(request.get("fault"), str):
        fault = faults.get(request["fault"])
        if fault is not None:
            specs.update({a.name: a for a in fault.args})
    unknown = sorted(set(request) - _ENVELOPE - set(specs))
    if unknown:
        raise ControlError("bad_argument", f"{command.name} takes no argument "
                           + ", ".join(repr(u) for u in unknown))
    out: dict[str, Any] = {}
    for name, spec in specs.items():
        if name in request:
            out[name] = spec.parse(request[name])
        elif spec.required:
            raise ControlError("bad_argument", f"{command.name} needs {name}")
        else:
            out[name] = spec.default
    return out


class ChannelControl(Generic[Target]):
    """Executes control requests on a set of drives of one family (protocol-free, one event
    loop owns it): ``execute(request) -> reply`` never raises; ``call`` raises ControlError.

    A family gives its tables (``commands``, ``faults``) and how a drive is addressed
    (:meth:`drive_id`). ``sync`` (e.g. ``RealtimeClock.sync``) runs before every request, so
    a server's drives are at the current time when a request reads or changes them."""

    commands: Mapping[str, Command[Target]]  # set by each family's subclass
    faults: FaultTable

    def __init__(self, drives: Sequence[Target], *,
                 sync: Callable[[], None] | None = None) -> None:
        self.drives = list(drives)
        self._sync = sync

    def drive_id(self, drive: Target) -> int:
        raise NotImplementedError

    def drive(self, drive_id: int | None) -> Target:
        if drive_id is None:
            if len(self.drives) == 1:
                return self.drives[0]
            raise ControlError("unknown_id", "id is needed: this channel serves drives "
                               + ",".join(str(self.drive_id(d)) for d in self.drives))
        for d in self.drives:
            if self.drive_id(d) == drive_id:
                return d
        raise ControlError("unknown_id", f"no drive with id {drive_id}")

    def ids(self) -> list[int]:
        return [self.drive_id(d) for d in self.drives]

    def execute(self, request: object) -> Reply:
        """One request (a dict, as decoded from JSON) -> its reply; never raises."""
        seq = request.get("seq") if isinstance(request, Mapping) else None
        try:
            reply = self._execute(request)
        except ControlError as exc:
            reply = {"ok": False, "kind": exc.kind, "error": str(exc)}
        head: Reply = {"ok": reply.pop("ok")}
        if isinstance(request, Mapping) and isinstance(request.get("cmd"), str):
            head["cmd"] = request["cmd"]
        if "id" in reply:
            head["id"] = reply.pop("id")
        head.update(reply)
        if isinstance(seq, str | int | float | bool):
            head["seq"] = seq
        return head

    def _execute(self, request: object) -> Reply:
        if not isinstance(request, Mapping):
            raise ControlError("malformed", "a request is a JSON object")
        name = request.get("cmd")
        command = self.commands.get(name) if isinstance(name, str) else None
        if command is None:
            raise ControlError("unknown_command",
                               f"cmd must be one of {', '.join(self.commands)}; got {name!r}")
        args = parse_args(command, request, self.faults)
        if self._sync is not None:
            self._sync()
        if command.run is None:
            assert command.run_channel is not None
            return command.run_channel(self, args)
        raw_id = request.get("id")
        if raw_id is not None and (isinstance(raw_id, bool) or not isinstance(raw_id, int)):
            raise ControlError("unknown_id", "id must be an integer")
        drive = self.drive(raw_id)
        reply = command.run(self, drive, args)
        reply.setdefault("id", self.drive_id(drive))
        return reply

    def call(self, cmd: str, drive_id: int | None = None, **args: Any) -> Reply:
        """As :meth:`execute` with keyword arguments; an error reply raises ControlError."""
        request: dict[str, Any] = {"cmd": cmd, **args}
        if drive_id is not None:
            request["id"] = drive_id
        reply = self.execute(request)
        if not reply["ok"]:
            raise ControlError(reply["kind"], reply["error"])
        return reply

    def state(self, drive_id: int | None = None) -> Reply:
        return self.call("state", drive_id)

    def fault(self, drive_id: int | None, fault: str, **params: Any) -> Reply:
        return self.call("fault", drive_id, fault=fault, **params)


def ping(ctl: ChannelControl[Any], a: dict[str, Any]) -> Reply:
    """The channel command ``ping``: the drive ids, commands and faults it serves."""
    return {"ok": True, "ids": ctl.ids(), "commands": sorted(ctl.commands),
            "faults": sorted(ctl.faults)}


# ---------------------------------------------------------------------- the load command
#: The ``load`` command's load keys, as in ``sim://`` URLs and ``servobus sim --load ...``
#: (servobus.sim.core.loads): every family's channel takes them.
LOAD_ARGS: tuple[Arg, ...] = (
    Arg("load", str, choices=tuple(loads.PRESETS), default=None,
        doc="a sample load: " + "; ".join(f"{k}: {p.doc}" for k, p in loads.PRESETS.items())),
    Arg("inertia", float, *loads.RANGES["inertia"], default=None,
        doc="load inertia / rotor inertia"),
    Arg("resonance", float, *loads.RANGES["resonance"], default=None,
        doc="resonance of the compliant coupling, Hz (0: rigid)"),
    Arg("load_torque", float, *loads.RANGES["load_torque"], default=None,
        doc="N m on the load side, against + (a weight lifted)"),
)


def load_request(args: Mapping[str, Any]) -> loads.LoadSettings:
    """The load a parsed ``load`` request sets (its :data:`LOAD_ARGS`)."""
    try:
        return loads.load_settings({a.name: args.get(a.name) for a in LOAD_ARGS})
    except ServobusError as exc:
        raise ControlError("bad_argument", str(exc)) from None


# ---------------------------------------------------------------------- the shaft's world
def ok(**extra: Any) -> Reply:
    """A command's reply: ``{"ok": true}`` and what it reports."""
    return {"ok": True, **extra}


class Shaft(Protocol):
    """What the world commands (``load``, ``block``) act on: a family's drive or motor."""

    def set_load(self, *, inertia: float | None = None,
                 friction: float | None = None) -> None: ...

    def set_disturbance(self, torque_nm: float) -> None: ...

    def set_blocked(self, blocked: bool) -> None: ...

    def world(self) -> dict[str, float | bool]: ...


ShaftT = TypeVar("ShaftT", bound=Shaft)


class Mechanics(Protocol):
    """The load model (servobus.sim.core.motor.Motor) a ``load`` request sets."""

    def set_mechanics(self, settings: loads.LoadSettings) -> None: ...

    def mechanics(self) -> dict[str, float]: ...


def apply_load(shaft: Shaft, mechanics: Mechanics, a: dict[str, Any]) -> Reply:
    """The ``load`` command: friction, external torque and the load (:data:`LOAD_ARGS`);
    replies with the world and the mechanics now."""
    settings = load_request(a)
    shaft.set_load(friction=a["friction"])
    if a["torque_nm"] is not None:
        shaft.set_disturbance(a["torque_nm"])
    if not settings.empty:
        mechanics.set_mechanics(settings)
    return ok(world=shaft.world(), mechanics=mechanics.mechanics())


def block(ctl: object, shaft: Shaft, a: dict[str, Any]) -> Reply:
    """The ``block`` command: the shaft blocked or free."""
    shaft.set_blocked(a["blocked"])
    return ok()


def world_commands(
        faults: Mapping[str, object],
        load: Callable[[Any, ShaftT, dict[str, Any]], Reply],
        fault: Callable[[Any, ShaftT, dict[str, Any]], Reply]) -> tuple[Command[ShaftT], ...]:
    """The ``load``, ``block`` and ``fault`` commands every family's channel takes, run by
    the family's ``load`` and ``fault`` handlers (``faults`` names the faults it injects)."""
    return (
        Command("load", (Arg("torque_nm", float, -100.0, 100.0, default=None),
                         Arg("friction", float, 0.0, 100.0, default=None, doc="N m, Coulomb"),
                         *LOAD_ARGS),
                load, "external torque, friction and the load: preset, inertia ratio, "
                      "resonance, load torque (docs/tuning.md)"),
        Command("block", (Arg("blocked", bool),), block, "block or free the shaft"),
        Command("fault", (Arg("fault", str, choices=tuple(faults)),), fault, "inject a fault"),
    )
